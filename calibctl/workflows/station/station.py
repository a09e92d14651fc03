"""One warm process for a sequence of units: serial in, capture + solve + store, verdict out, next.

The loop reads the next serial (a line of stdin - a barcode scanner is a keyboard - or of ``--serials
FILE``), captures the folder ``source_template.format(serial=...)`` with the station's board, solves it
(``workflows.camera.capture.calibrate``: the same gates, lint and store as ``calibctl calibrate``) and
reports one ``UnitResult``; then it waits for the next serial. Imports, the store's migrations check and
the detection worker processes are paid once, at start-up (``warm_up``), not per unit.

A unit that cannot run is a result line, never the end of the loop: a serial that is not a serial, a
serial already done in this run, a missing folder, an unknown board, unreadable images (each with
status "error" and the message and hint a one-shot command would print).

Ctrl-C (SIGINT):
  * while waiting for a serial: the station ends cleanly (``StationSummary.interrupted``; exit 0);
  * while a unit's images are being detected: that unit is cancelled - nothing is stored, its line says
    "cancelled" - and the station waits for the next serial;
  * once detection is over the unit's images, session and calibration are written and solved (a
    fraction of its time); a Ctrl-C then is held until the unit is complete, and ends the station after
    its verdict, so no unit is ever half stored.
"""

from __future__ import annotations

import re
import signal
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

from calibctl.artifacts.common import SERIAL_PATTERN
from calibctl.config import Settings
from calibctl.errors import CalibctlError, UsageError
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.camera.capture import CaptureObserver, CaptureRequest, calibrate
from calibctl.workflows.camera.solve import MODEL_CHOICES

PASS, FAIL, ERROR, CANCELLED = "pass", "fail", "error", "cancelled"
SERIAL_SLOT = "{serial}"


@dataclass(frozen=True)
class StationRequest:
    board: str
    source_template: str  # DIR/{serial}: the folder (or glob, list file) a unit's pictures arrive in
    model: str = "k1k2"


@dataclass(frozen=True)
class UnitResult:
    """One unit's line. ``unit_s``: serial read to verdict out, seconds."""

    serial: str
    status: str  # pass | fail | error | cancelled
    message: str
    hint: str | None = None
    session_id: str | None = None
    version: int | None = None
    rms_px: float | None = None
    views: int | None = None
    unit_s: float = 0.0

    def as_json(self) -> dict[str, Any]:
        return {"serial": self.serial, "status": self.status, "message": self.message, "hint": self.hint,
                "session_id": self.session_id, "version": self.version, "rms_px": self.rms_px,
                "views": self.views, "unit_s": round(self.unit_s, 4)}


@dataclass
class StationSummary:
    units: list[UnitResult] = field(default_factory=list)
    interrupted: bool = False  # ended by Ctrl-C (between units, or held until a unit was complete)


def check_request(request: StationRequest) -> None:
    """What is wrong with the whole station run is a usage error (exit 2) before the first unit."""
    if SERIAL_SLOT not in request.source_template:
        raise UsageError(f"--source-template '{request.source_template}' has no {SERIAL_SLOT}",
                         "name the folder each unit's pictures arrive in, e.g. /data/shots/{serial}")
    if request.model not in MODEL_CHOICES:
        raise UsageError(f"unknown model '{request.model}'", f"choose one of {', '.join(MODEL_CHOICES)}")


def warm_up(settings: Settings) -> None:
    """Pay the start-up once: the detection worker processes (``core.capture.worker_pool``)."""
    from calibctl.core.capture import worker_pool

    if settings.jobs > 1:
        worker_pool.warm(settings.jobs)


class _Interrupts:
    """SIGINT while the station may stop (waiting, detecting) raises KeyboardInterrupt; otherwise it is
    held (``pending``) until the unit is complete."""

    def __init__(self) -> None:
        self.cancellable = True
        self.pending = False
        self._previous: Any = None

    def __enter__(self) -> _Interrupts:
        self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        signal.signal(signal.SIGINT, self._previous)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.cancellable:
            raise KeyboardInterrupt
        self.pending = True


class _UnitObserver(CaptureObserver):
    """Detection may be cancelled; from the last image's outcome on, the unit runs to its end."""

    def __init__(self, interrupts: _Interrupts, inner: CaptureObserver) -> None:
        self.interrupts, self.inner = interrupts, inner

    def folder_started(self, total: int) -> None:
        self.inner.folder_started(total)

    def image_done(self, done: int, total: int, name: str, status: str) -> None:
        if done == total:
            self.interrupts.cancellable = False
        self.inner.image_done(done, total, name, status)


def _unit(settings: Settings, request: StationRequest, serial: str, observer: CaptureObserver) -> UnitResult:
    source = request.source_template.replace(SERIAL_SLOT, serial)
    if not any(ch in source for ch in "*?[") and not Path(source).exists():
        return UnitResult(serial, ERROR, f"no pictures for {serial}: {source} does not exist",
                          "put the unit's pictures there (or check the serial), then scan it again")
    kind = sources.resolve_source(source).kind
    if kind not in sources.IMAGE_SETS:
        return UnitResult(serial, ERROR, f"{source} is a {kind}; the station reads a folder, glob or list per unit",
                          "point --source-template at the folder each unit's pictures are saved in")
    done = calibrate(settings, CaptureRequest(serial, request.board, source, jobs=settings.jobs), model=request.model,
                     observer=observer)
    session = done.capture.session
    if done.solve is None:
        reasons = "; ".join(g.reason for g in session.gates if not g.passed and g.reason) or "the distance gauge failed"
        return UnitResult(serial, FAIL, f"capture rejected: {reasons}", session_id=session.session_id,
                          views=len(session.views))
    art = done.solve.artifact
    status = PASS if art.status == "accepted" else FAIL
    return UnitResult(serial, status, f"calibration v{art.version} {art.status}", session_id=session.session_id,
                      version=art.version, rms_px=art.rms_px, views=len(session.views))


def run_station(settings: Settings, request: StationRequest, serials: Iterable[str],
                report: Callable[[UnitResult], None], observer: Callable[[], CaptureObserver] = CaptureObserver,
                ) -> StationSummary:
    """Calibrate one unit per serial line until the lines end or Ctrl-C (see the module docstring).

    ``report(result)`` is called once per non-blank line, as soon as its unit is done; ``observer()``
    makes each unit's capture observer (the CLI's progress display).
    """
    check_request(request)
    summary = StationSummary()
    seen: dict[str, int] = {}
    lines: Iterator[str] = iter(serials)
    with _Interrupts() as interrupts:
        while True:
            interrupts.cancellable, interrupts.pending = True, False
            try:
                line = next(lines, None)
            except KeyboardInterrupt:
                summary.interrupted = True
                break
            if line is None:
                break
            serial = line.strip()
            if not serial:
                continue
            start = time.perf_counter()
            result = _checked_serial(serial, seen)
            if result is None:
                try:
                    result = _unit(settings, request, serial, _UnitObserver(interrupts, observer()))
                except KeyboardInterrupt:
                    result = UnitResult(serial, CANCELLED, "cancelled (Ctrl-C) while its images were detected; "
                                        "nothing was stored", "scan the serial again to calibrate it")
                except CalibctlError as exc:
                    result = UnitResult(serial, ERROR, exc.message, exc.hint)
                if result.status in (PASS, FAIL):
                    seen[serial] = len(summary.units) + 1
            result = UnitResult(**{**result.__dict__, "unit_s": time.perf_counter() - start})
            summary.units.append(result)
            report(result)
            if interrupts.pending:
                summary.interrupted = True
                break
    return summary


def _checked_serial(serial: str, seen: dict[str, int]) -> UnitResult | None:
    if not re.fullmatch(SERIAL_PATTERN, serial):
        return UnitResult(serial, ERROR, f"'{serial}' is not a serial",
                          "a serial is letters, digits and . _ : - (no spaces, no '@'); scan the label again")
    if serial in seen:
        return UnitResult(serial, ERROR, f"{serial} was already calibrated in this run (unit {seen[serial]}); "
                          "not calibrated again", "scan the next unit; to recalibrate this one, run calibctl calibrate")
    return None
