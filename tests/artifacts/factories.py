"""Small, valid artifacts for tests (deterministic: no clocks, no randomness)."""

from __future__ import annotations

import datetime as dt

from calibctl.artifacts.board import BoardRevision, SquareMeasurement
from calibctl.artifacts.calibration import (
    UNSEALED,
    CalibrationArtifact,
    DistortionModelInfo,
    HeldOut,
    Provenance,
    Uncertainty,
    ViewResult,
)

FIXED_TIME = dt.datetime(2026, 3, 11, 9, 30, tzinfo=dt.UTC)


def measured_board(name: str = "A17", revision: int = 1, square_mm: float = 25.03) -> BoardRevision:
    return BoardRevision(
        name=name,
        revision=revision,
        kind="chessboard",
        cols=9,
        rows=6,
        measurement=SquareMeasurement(
            status="measured",
            square_size_m=square_mm / 1000.0,
            uncertainty_m=0.00002,
            instrument="calipers",
            measured_by="qa",
            measured_on=dt.date(2026, 3, 11),
        ),
        created_at=FIXED_TIME,
        created_by="qa",
    )


def measured_board_args(name: str) -> list[str]:
    """`board add NAME` of a measured 9x6 chessboard with 25 mm squares, as command-line arguments."""
    grid = ["--kind", "chessboard", "--cols", "9", "--rows", "6", "--square-mm", "25"]
    measured = ["--uncertainty-mm", "0.02", "--instrument", "calipers", "--measured-by", "qa"]
    return ["board", "add", name, *grid, *measured, "--measured-on", "2026-03-11"]


def nominal_board(name: str = "N1", square_mm: float = 23.0) -> BoardRevision:
    return BoardRevision(
        name=name,
        revision=1,
        kind="chessboard",
        cols=9,
        rows=6,
        measurement=SquareMeasurement(status="nominal", square_size_m=square_mm / 1000.0),
        created_at=FIXED_TIME,
        created_by="someone",
    )


def calibration(
    serial: str = "CAM-0001",
    version: int = 1,
    status: str = "accepted",
    fx: float = 800.0,
    image_size: tuple[int, int] = (640, 480),
    cx: float = 320.0,
    cy: float = 240.0,
    board: BoardRevision | None = None,
) -> CalibrationArtifact:
    artifact = CalibrationArtifact(
        serial=serial,
        version=version,
        status=status,  # type: ignore[arg-type]
        image_size=image_size,
        camera_matrix=((fx, 0.0, cx), (0.0, fx, cy), (0.0, 0.0, 1.0)),
        dist_coeffs=[-0.2814, 0.0977, 0.0, 0.0, 0.0],
        model=DistortionModelInfo(
            name="k1k2",
            opencv_flags=0,
            flag_names=["CALIB_FIX_K3", "CALIB_ZERO_TANGENT_DIST", "CALIB_FIX_ASPECT_RATIO"],
            free_parameters=["fx", "fy", "cx", "cy", "k1", "k2"],
        ),
        stdev=Uncertainty(
            sigma={"fx": 0.84, "fy": 0.84, "cx": 0.51, "cy": 0.47, "k1": 0.002, "k2": 0.006},
            residual_count=108,  # one 9x6 view: 54 corners
            parameter_count=11,
        ),
        rms_px=0.284,
        held_out=HeldOut(k_folds=5, rms_px=0.30, outer_ring_rms_px=0.31, fit_outer_ring_rms_px=0.29),
        board=board or measured_board(),
        views=[ViewResult(name="img01.png", rms_px=0.284, rvec=(0.2, -0.3, 0.05), tvec_m=(0.02, -0.01, 0.6))],
        provenance=Provenance(
            calibctl_version="0.1.0",
            opencv_version="5.0.0",
            station="st1",
            operator="op",
            created_at=FIXED_TIME,
        ),
        content_sha256=UNSEALED,
    )
    return artifact.sealed()
