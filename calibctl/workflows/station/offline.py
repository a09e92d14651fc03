"""A unit calibrated while the central store is away: captured and solved here, queued in the spool.

The capture is ``calibctl capture``'s own (``capture(..., into=SpoolCapture)``): the same detection,
gates and session, with the board taken from the boards the spool (or this run) has seen and the images
copied into the spool. An accepted session is solved, validated and linted as ``calibctl solve`` does
(``build_artifact``); the calibration is queued unsealed, and gets its version from the central store
when the spool is synced (``workflows.station.sync``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.session import CaptureSession
from calibctl.config import Settings
from calibctl.core.capture.arrivals import EarlyDetections
from calibctl.errors import NotFoundError
from calibctl.store.spool import Spool
from calibctl.workflows.camera.capture import CaptureObserver, CaptureRequest, capture
from calibctl.workflows.camera.solve import SolveRequest, build_artifact


@dataclass(frozen=True)
class Queued:
    """A queued unit: its spool record number, session and (when the gates passed) calibration."""

    seq: int
    session: CaptureSession
    artifact: CalibrationArtifact | None


class SpoolCapture:
    """The ``CaptureStore`` a capture writes to while the store is away."""

    def __init__(self, spool: Spool, boards: dict[str, BoardRevision], why: str) -> None:
        self.spool, self.boards, self.why = spool, boards, why
        self.image_dir: Path = spool.image_dir
        self.session: CaptureSession | None = None

    def get_board(self, name: str, revision: int | None = None) -> BoardRevision:
        seen = self.boards.get(name)
        if seen is not None and revision in (None, seen.revision):
            return seen
        board = self.spool.board(name, revision)
        if board is None:
            ref = name if revision is None else f"{name}@{revision}"
            raise NotFoundError(
                f"board {ref} is unknown offline: {self.why}, and this station's spool has never seen it",
                "bring the store back, or run the station once while it is reachable",
            )
        return board

    def put_image(self, data: bytes, *, retention_days: int) -> str:
        return self.spool.put_images([data])[0]

    def put_images(self, images: Sequence[bytes], *, retention_days: int) -> list[str]:
        return self.spool.put_images(images)

    def add_session(self, session: CaptureSession) -> None:
        self.session = session  # queued with its calibration, in one spool transaction (queue_unit)


def queue_unit(
    settings: Settings,
    spool: Spool,
    boards: dict[str, BoardRevision],
    request: CaptureRequest,
    model: str,
    observer: CaptureObserver,
    why: str,
    detected: EarlyDetections | None = None,
) -> Queued:
    """Capture, gate and solve one unit into the spool (``why``: what made the station go offline;
    ``detected``: its pictures detected as they landed, watch mode)."""
    sink = SpoolCapture(spool, boards, why)
    captured = capture(settings, request, observer, into=sink, detected=detected)
    return queue_solved(
        settings, spool, captured.session, model, session_stored=False, passed=captured.passed
    )


def queue_solved(
    settings: Settings,
    spool: Spool,
    session: CaptureSession,
    model: str,
    *,
    session_stored: bool,
    passed: bool = True,
) -> Queued:
    """Solve an accepted session here and queue it (``session_stored``: the session itself reached the
    store)."""
    artifact = None
    if passed:
        artifact, _ = build_artifact(
            session, SolveRequest(session_id=session.session_id, model=model), settings
        )
    return Queued(spool.queue(session, artifact, session_stored=session_stored), session, artifact)
