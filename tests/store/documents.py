"""Small valid documents for store tests (deterministic; artifacts and boards come from tests.artifacts)."""

from __future__ import annotations

import datetime as dt

from calibctl.artifacts.check import CheckEvent, DistanceCheck, RegionCheck
from calibctl.artifacts.fleet import FleetEvent
from calibctl.artifacts.health import HealthReport
from calibctl.artifacts.session import CaptureSession, ImageOutcome, MetricGauge, ViewCorners
from tests.artifacts.factories import FIXED_TIME, measured_board


def capture_session(
    session_id: str = "0123456789ab",
    serial: str = "CAM-0001",
    status: str = "accepted",
    minutes_after: int = 0,
) -> CaptureSession:
    started = FIXED_TIME + dt.timedelta(minutes=minutes_after)
    return CaptureSession(
        session_id=session_id,
        serial=serial,
        board=measured_board(),
        source="/data/cam-0001/run1",
        source_kind="folder",
        station="st1",
        operator="op",
        started_at=started,
        finished_at=started + dt.timedelta(seconds=42),
        image_size=(640, 480),
        status=status,  # type: ignore[arg-type]
        outcomes=[
            ImageOutcome(
                name="img01.png", status="accepted", sha256="ab" * 32, image_size=(640, 480), corners_found=4
            ),
            ImageOutcome(name="img02.png", status="no_board", reason="no chessboard found"),
        ],
        views=[
            ViewCorners(
                name="img01.png",
                image_sha256="ab" * 32,
                corner_ids=[0, 1, 9, 10],
                corners_px=[(100.25, 80.5), (130.125, 80.75), (100.5, 110.0625), (130.0, 110.25)],
                tilt_deg=24.5,
                tilt_direction="top left",
            )
        ],
        calibctl_version="0.1.0",
        opencv_version="5.0.0",
    )


def gauged_session(
    session_id: str, ratio: float, serial: str = "CAM-0001", board_name: str = "A17"
) -> CaptureSession:
    """``capture_session`` with a metric gauge that read ``ratio`` (failed outside 0.99-1.01), on board
    ``board_name``@1."""
    distance = DistanceCheck(
        reference_m=0.45,
        reference_sigma_m=0.0005,
        recovered_m=0.45 * ratio,
        spread=0.001,
        ratio=ratio,
        ratio_limits=(0.99, 1.01),
        passed=0.99 <= ratio <= 1.01,
    )
    return capture_session(session_id, serial).model_copy(
        update={
            "board": measured_board(board_name),
            "metric_gauge": MetricGauge(distance=distance, lens_model="k1k2", reference_source="fixture/"),
        }
    )


def check_event(serial: str, version: int, sha: str, n: int, passed: bool = True) -> CheckEvent:
    region = RegionCheck(
        region="overall",
        check_rms_px=0.2,
        reference_rms_px=0.2,
        ratio=1.0,
        limit=1.5,
        corners=40,
        tested=True,
        passed=passed,
    )
    return CheckEvent(
        check_id=f"{n:012x}",
        serial=serial,
        version=version,
        calibration_sha256=sha,
        source="folder x",
        station="st1",
        operator="qa",
        at=FIXED_TIME + dt.timedelta(minutes=n),
        image_size=(640, 480),
        images=3,
        views=["a.png"],
        view_rms_px=[0.2],
        regions=[region],
        alpha=0.01,
        passed=passed,
    )


def fleet_event(kind: str, robot: str = "amr-001", **fields: object) -> FleetEvent:
    """A fleet log step by qa at st1, FIXED_TIME: ``register`` (serials=, rigs=) or ``assign`` (serial=,
    version=)."""
    return FleetEvent(
        kind=kind,
        robot=robot,
        actor="qa",
        station="st1",
        at=FIXED_TIME,  # type: ignore[arg-type]
        reason=f"test {kind}",
        **fields,
    )  # type: ignore[arg-type]


def health_report(
    serial: str, robot: str = "amr-001", source_id: str = "r-1", **fields: object
) -> HealthReport:
    """A passing check report of ``serial`` from ``robot`` at FIXED_TIME (override kind and numbers with
    fields)."""
    numbers = fields or {"kind": "check", "rms_px": 0.3, "verdict": "pass", "temperature_c": 25.0}
    return HealthReport(source_id=source_id, serial=serial, robot=robot, time=FIXED_TIME, **numbers)  # type: ignore[arg-type]
