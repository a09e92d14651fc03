"""One warm process for a sequence of units: serial in, capture + solve + store, verdict out, next.

The loop reads the next serial (a line of stdin - a barcode scanner is a keyboard - or of ``--serials
FILE``), captures the folder ``source_template.format(serial=...)`` with the station's board, solves it
(``capture`` then ``solve``: the same gates, lint and store as ``calibctl calibrate``) and
reports one ``UnitResult``; then it waits for the next serial. Imports, the store's migrations check and
the detection worker processes are paid once, at start-up (``warm_up``), not per unit; a SQLite store is
held open for the station's life, so that a unit's closes do not checkpoint its log (``_sqlite_kept_open``).

A unit that cannot run is a result line, never the end of the loop: a serial that is not a serial, a
serial already done in this run, a missing folder, an unknown board, unreadable images (each with
status "error" and the message and hint a one-shot command would print).

The store away (``DatabaseUnreachableError``: no server, network cut): the unit is captured, gated and
solved here and queued in the station's spool (``workflows.station.offline``); its line says "queued".
Before each unit the station syncs what is queued (``workflows.station.sync``, one line "synced" per
record stored, with its version); while anything stays queued, new units queue behind it, so a
serial's versions keep the order its units were calibrated in.

Camera mode (``StationRequest.camera``, ``LiveCamera``): the unit's own camera is plugged into the station's
port and captured live, as ``calibctl capture --source /dev/videoN`` does (frame selection, the live gates),
until the gates pass (with ``max_views`` views) or ``duration_s`` is up. The unit is held in memory
(``workflows.station.held``) until its stream and gates are over, then stored - or queued - whole: a camera
that cannot be opened or stops delivering frames mid-unit (unplugged) is an error line with nothing stored,
and a store that goes away does not make the operator capture the unit again.

Watch mode (``StationRequest.watch``, ``workflows.station.watch``): after the serial the station waits for
the unit's pictures in its folder and detects each as it lands; once the unit is complete the capture runs
with those outcomes. The line adds ``after_last_image_s``, from the last picture landing to the verdict.

Ctrl-C (SIGINT):
  * while waiting for a serial: the station ends cleanly (``StationSummary.interrupted``; exit 0);
  * while waiting for a unit's pictures (watch mode): that unit is cancelled, as below;
  * while a unit's images are being detected, or its camera streams (or the spool synced before it): that unit
    is cancelled - nothing of it is stored, its line says "cancelled" - and the station waits for the next
    serial;
  * once detection is over (a camera unit: its stream and gates) the unit's images, session and calibration
  are
    written and solved (a fraction of its time); a Ctrl-C then is held until the unit is complete, and ends
    the station after its verdict, so no unit is ever half stored.
"""

from __future__ import annotations

import contextlib
import re
import signal
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import FrameType
from typing import Any

from calibctl import bounded
from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.common import SERIAL_PATTERN
from calibctl.artifacts.session import CaptureSession
from calibctl.config import Settings
from calibctl.core.capture.arrivals import EarlyDetections
from calibctl.core.intrinsics.solve import DEFAULT_MODEL
from calibctl.errors import (
    CalibctlError,
    DatabaseUnreachableError,
    IntegrityError,
    UnverifiedRecord,
    UsageError,
)
from calibctl.store.repository import Store
from calibctl.store.spool import Spool, default_spool_path
from calibctl.workflows.board.boards import board_ref, board_spec
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.camera.capture import (
    CaptureObserver,
    CaptureRequest,
    FrameDecision,
    SelectionProgress,
    capture,
    check_stream_stops,
)
from calibctl.workflows.camera.distance_gauge import gauge_model
from calibctl.workflows.camera.solve import MODEL_CHOICES, SolveRequest, solve, start_numbers
from calibctl.workflows.station.held import HeldCapture, spool_images, write_to_store
from calibctl.workflows.station.offline import Queued, SpoolCapture, queue_solved, queue_unit
from calibctl.workflows.station.sync import SyncedUnit, open_spool, sync
from calibctl.workflows.station.watch import Watched, WatchRule, check_rule, watch_unit
from calibctl.workflows.store_admin import keys

PASS, FAIL, ERROR, CANCELLED, QUEUED, SYNCED = "pass", "fail", "error", "cancelled", "queued", "synced"
SERIAL_SLOT = "{serial}"
_SYNC_HINT = "it is stored when the store is back: before the next unit, or by `calibctl station sync`"


@dataclass(frozen=True)
class LiveCamera:
    """The station's camera port: each unit is captured live from ``device`` (the unit's own camera, plugged
    in), until the gates pass with ``max_views`` views (None: as soon as they pass) or ``duration_s`` is
    up."""

    device: str  # /dev/videoN or an index, as `calibctl capture --source` names a camera
    max_views: int | None = None
    duration_s: float | None = None


@dataclass(frozen=True)
class StationRequest:
    board: str
    source_template: str | None  # DIR/{serial}: the folder (or glob, list file) a unit's pictures arrive in
    model: str = DEFAULT_MODEL
    spool: Path | None = None  # None: store.spool.default_spool_path
    watch: WatchRule | None = None  # watch mode: wait for each unit's pictures, detect them as they land
    camera: LiveCamera | None = None  # instead of source_template: each unit live from the station's camera


@dataclass(frozen=True)
class UnitResult:
    """One unit's line. ``unit_s``: serial read to verdict out, seconds; ``after_last_image_s`` (watch mode):
    the unit's last picture landing in its folder (its ctime) to verdict out, seconds (camera mode: the last
    frame selected, the one that stopped the stream, to verdict out)."""

    serial: str
    status: str  # pass | fail | error | cancelled | queued (in the spool) | synced (a queued one stored)
    message: str
    hint: str | None = None
    session_id: str | None = None
    version: int | None = None
    rms_px: float | None = None
    views: int | None = None
    unit_s: float = 0.0
    verdict: str | None = None  # queued / synced: pass or fail, as the unit's own line would have said
    spool_record: int | None = None  # queued / synced: the record number, the order of the sync
    after_last_image_s: float | None = None
    last_image_at: float | None = field(
        default=None, repr=False
    )  # epoch s; after_last_image_s is measured from it

    def as_json(self) -> dict[str, Any]:
        return {
            "serial": self.serial,
            "status": self.status,
            "message": self.message,
            "hint": self.hint,
            "session_id": self.session_id,
            "version": self.version,
            "rms_px": self.rms_px,
            "views": self.views,
            "unit_s": round(self.unit_s, 4),
            "verdict": self.verdict,
            "spool_record": self.spool_record,
            "after_last_image_s": None
            if self.after_last_image_s is None
            else round(self.after_last_image_s, 4),
        }


@dataclass
class StationSummary:
    units: list[UnitResult] = field(default_factory=list)
    interrupted: bool = False  # ended by Ctrl-C (between units, or held until a unit was complete)


def check_request(request: StationRequest) -> None:
    """What is wrong with the whole station run is a usage error (exit 2) before the first unit."""
    if (request.source_template is None) == (request.camera is None):
        raise UsageError(
            "the station takes one source: --source-template (each unit's pictures in a folder) or "
            "--camera (each unit live from the station's camera)",
            "e.g. --source-template /data/shots/{serial}, or --camera /dev/video0",
        )
    if request.model not in MODEL_CHOICES:
        raise UsageError(f"unknown model '{request.model}'", f"choose one of {', '.join(MODEL_CHOICES)}")
    if request.camera is not None:
        _check_camera(request.camera, request.watch)
        return
    assert request.source_template is not None
    if SERIAL_SLOT not in request.source_template:
        raise UsageError(
            f"--source-template '{request.source_template}' has no {SERIAL_SLOT}",
            "name the folder each unit's pictures arrive in, e.g. /data/shots/{serial}",
        )
    if request.watch is not None:
        check_rule(request.watch)
        if any(ch in request.source_template for ch in "*?["):
            raise UsageError(
                f"--watch watches a folder per unit; --source-template '{request.source_template}' is a glob",
                "give the folder the camera app saves each unit's pictures in: DIR/{serial}",
            )


def _check_camera(camera: LiveCamera, watch: WatchRule | None) -> None:
    if watch is not None:
        raise UsageError(
            "--watch waits for pictures in a folder; --camera captures each unit live",
            "leave out --watch (and --views, --done-file) with --camera",
        )
    try:
        kind: str | None = sources.resolve_source(camera.device).kind
    except CalibctlError:  # an empty or missing path: worded for --source
        kind = None
    if kind != sources.CAMERA:
        raise UsageError(
            f"--camera {camera.device} is not a camera",
            "give the device the unit's camera appears as: /dev/videoN or an index such as 0 (a folder "
            "of pictures per unit is --source-template DIR/{serial})",
        )
    check_stream_stops(camera.max_views, camera.duration_s)


def warm_up(settings: Settings, request: StationRequest) -> None:
    """Pay the start-up once: the detection worker processes (``core.capture.worker_pool``) of folder units (a
    camera's frames are detected one by one as they arrive, in this process)."""
    from calibctl.core.capture import worker_pool

    if settings.jobs > 1 and request.camera is None:
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
    """Detection may be cancelled; from the last image's outcome on (a camera unit: from the end of its stream
    and gates, ``unit_complete``), the unit runs to its end."""

    def __init__(
        self,
        interrupts: _Interrupts,
        inner: CaptureObserver,
        early: Callable[[CaptureSession], None] | None = None,
    ) -> None:
        self.interrupts, self.inner, self.early = interrupts, inner, early
        self.last_frame_at: float | None = (
            None  # epoch s: a stream's last frame selected (a camera unit's stop)
        )

    def folder_started(self, total: int) -> None:
        self.interrupts.cancellable = True  # an offline capture after a failed online one starts from nothing
        self.inner.folder_started(total)

    def image_done(self, done: int, total: int, name: str, status: str) -> None:
        if done == total:
            self.interrupts.cancellable = False
        self.inner.image_done(done, total, name, status)

    def frame_done(self, decision: FrameDecision, progress: SelectionProgress, t_s: float) -> None:
        self.last_frame_at = time.time()
        self.inner.frame_done(decision, progress, t_s)

    def unit_complete(self) -> None:
        self.interrupts.cancellable = False

    def session_built(self, session: CaptureSession) -> None:
        if self.early is not None:
            self.early(session)
        self.inner.session_built(session)


@contextlib.contextmanager
def _early_numbers(
    settings: Settings, request: StationRequest
) -> Iterator[Callable[[CaptureSession], None] | None]:
    """What starts an accepted session's solve numbers on another thread as soon as its gates are final, so
    they are computed while the session and its images are written and read back (about 0.1 s of a unit's
    main thread); the solve then takes them (``workflows.camera.solve.start_numbers``). With ``--jobs`` 1
    nothing: that is the plain sequential order, on one thread."""
    if settings.jobs < 2:
        yield None
        return
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="calibctl-early-numbers") as executor:
        yield lambda session: start_numbers(
            session, _solve_request(session, request), settings.jobs, executor
        )


def _solve_request(session: CaptureSession, request: StationRequest) -> SolveRequest:
    return SolveRequest(session_id=session.session_id, model=request.model)


class _Offline:
    """The spool, opened when first needed (a station whose store never goes away writes one board list);
    a spool file that exists is opened at start, so another station's or store's is refused then (exit 2)."""

    def __init__(self, settings: Settings, path: Path | None) -> None:
        self.settings = settings
        self.path = path or default_spool_path(settings.station_file, settings.db_url)
        self.boards: dict[str, BoardRevision] = {}  # served by the store in this run
        self._spool = open_spool(settings, self.path) if self.path.exists() else None

    def spool(self) -> Spool:
        if self._spool is None:
            self._spool = open_spool(self.settings, self.path)
        return self._spool

    def remember(self, board: BoardRevision) -> None:
        """Keep the board the store served, for a later run that starts with the store away."""
        if self.boards.get(board.name) != board:
            self.boards[board.name] = board
            # a cache: the unit itself is stored, and a spool that cannot be written says so when it is used
            with contextlib.suppress(CalibctlError):
                self.spool().remember_board(board)

    def before_unit(self, report: Callable[[UnitResult], None]) -> tuple[str, str] | None:
        """Sync what is queued; why the next unit must be queued too and the hint its line gives (None:
        nothing is left queued)."""
        if self._spool is None or self._spool.counts()[0] == 0:
            return None
        try:
            done = sync(self.settings, self._spool)
        except CalibctlError as exc:  # another process holds the sync lock
            return exc.message, _SYNC_HINT
        for unit in done.synced:
            report(_synced_line(unit))
        if isinstance(
            done.error, IntegrityError | UnverifiedRecord
        ):  # a refused record: its hint says what to do
            return done.error.message, done.error.hint or _SYNC_HINT
        if done.error is not None:
            return done.error.message, _SYNC_HINT
        return None if done.left == 0 else (f"{done.left} unit(s) are still queued", _SYNC_HINT)

    def __enter__(self) -> _Offline:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._spool is not None:
            self._spool.close()


def _rejected(session: CaptureSession) -> str:
    reasons = (
        "; ".join(g.reason for g in session.gates if not g.passed and g.reason) or "the distance gauge failed"
    )
    return f"capture rejected: {reasons}"


def _unit_board(
    settings: Settings, request: StationRequest, offline: _Offline
) -> tuple[BoardRevision, str | None]:
    """The unit's board from the store, else (the store away) from the spool as the capture into it will find
    it;
    and why the unit goes to the spool (None: the store answered)."""
    name, revision = board_ref(request.board)
    try:
        with Store.open(settings.db_url, trusted=keys.read_trust(settings)) as store:
            board = store.get_board(name, revision)
    except DatabaseUnreachableError as exc:
        return SpoolCapture(offline.spool(), offline.boards, exc.message).get_board(
            name, revision
        ), exc.message
    offline.remember(board)
    return board, None


def _watched(
    settings: Settings, request: StationRequest, source: str, offline: _Offline
) -> tuple[Watched, str | None]:
    """Watch mode: the unit's pictures, detected as they land, with the board the capture will use; and why
    the unit goes to the spool (None: the store answered)."""
    assert request.watch is not None
    board, away = _unit_board(settings, request, offline)
    return watch_unit(Path(source), request.watch, board_spec(board), settings.jobs), away


def _capture_request(
    settings: Settings, request: StationRequest, serial: str, source: str, camera: LiveCamera | None = None
) -> CaptureRequest:
    """A unit's capture (``camera``: live, with its stop rule, and Ctrl-C cancels it). As `calibctl
    calibrate`: the gates judge through the lens model the session will be solved with."""
    return CaptureRequest(
        serial,
        request.board,
        source,
        jobs=settings.jobs,
        gauge_model=gauge_model(request.model),
        lens_model=None if request.model == "auto" else request.model,
        max_views=None if camera is None else camera.max_views,
        duration_s=None if camera is None else camera.duration_s,
        cancel_on_interrupt=camera is not None,
    )


def _camera_unit(
    settings: Settings,
    request: StationRequest,
    serial: str,
    observer: _UnitObserver,
    offline: _Offline,
    why_queue: tuple[str, str] | None,
) -> UnitResult:
    """One unit live from the station's camera, held in memory until its stream and gates are over
    (``workflows.station.held``), then stored whole, or queued whole when the store is away."""
    assert request.camera is not None
    board, away = _unit_board(settings, request, offline)
    if why_queue is None and away is not None:
        why_queue = away, _SYNC_HINT
    unit = _capture_request(settings, request, serial, request.camera.device, request.camera)
    held = HeldCapture(board)
    captured = capture(settings, unit, observer, into=held)
    observer.unit_complete()  # from here the unit is written whole: a Ctrl-C waits for its verdict
    session = captured.session
    if why_queue is None:
        try:
            write_to_store(settings, held)
        except DatabaseUnreachableError as exc:
            why_queue = exc.message, _SYNC_HINT
        else:
            result = _solved_unit(settings, request, session, offline)
    if why_queue is not None:
        spool = offline.spool()
        spool_images(spool, held)
        result = _queued_line(
            queue_solved(
                settings, spool, session, request.model, session_stored=False, passed=captured.passed
            ),
            *why_queue,
        )
    return replace(result, last_image_at=observer.last_frame_at)


def _unit(
    settings: Settings,
    request: StationRequest,
    serial: str,
    observer: _UnitObserver,
    offline: _Offline,
    why_queue: tuple[str, str] | None,
) -> UnitResult:
    if request.camera is not None:
        return _camera_unit(settings, request, serial, observer, offline, why_queue)
    assert request.source_template is not None
    source = request.source_template.replace(SERIAL_SLOT, serial)
    watched = None
    if request.watch is not None:
        if Path(source).exists() and not Path(source).is_dir():
            return UnitResult(
                serial,
                ERROR,
                f"{source} is not a folder; --watch watches a folder per unit",
                "point --source-template at the folder the camera app saves each unit's pictures in",
            )
        watched, away = _watched(settings, request, source, offline)
        if why_queue is None and away is not None:  # not a second connect timeout for the capture
            why_queue = away, _SYNC_HINT
    if not any(ch in source for ch in "*?[") and not Path(source).exists():
        return UnitResult(
            serial,
            ERROR,
            f"no pictures for {serial}: {source} does not exist",
            "put the unit's pictures there (or check the serial), then scan it again",
        )
    kind = sources.resolve_source(source).kind
    if kind not in sources.IMAGE_SETS:
        return UnitResult(
            serial,
            ERROR,
            f"{source} is a {kind}; the station reads a folder, glob or list per unit",
            "point --source-template at the folder each unit's pictures are saved in",
        )
    unit = _capture_request(settings, request, serial, source)
    detected = None if watched is None else watched.detected
    if why_queue is None:
        try:
            result = _online_unit(settings, request, unit, observer, offline, detected)
        except (
            DatabaseUnreachableError
        ) as exc:  # before its session was stored: captured again, into the spool
            why_queue = exc.message, _SYNC_HINT
    if why_queue is not None:
        why, hint = why_queue
        queued = queue_unit(
            settings, offline.spool(), offline.boards, unit, request.model, observer, why, detected
        )
        result = _queued_line(queued, why, hint)
    return result if watched is None else replace(result, last_image_at=watched.last_in_s)


def _online_unit(
    settings: Settings,
    request: StationRequest,
    unit: CaptureRequest,
    observer: CaptureObserver,
    offline: _Offline,
    detected: EarlyDetections | None,
) -> UnitResult:
    session = capture(settings, unit, observer, detected=detected).session
    offline.remember(session.board)
    return _solved_unit(settings, request, session, offline)


def _solved_unit(
    settings: Settings, request: StationRequest, session: CaptureSession, offline: _Offline
) -> UnitResult:
    """A stored session's line: rejected, or solved and stored (its calibration queued when the store went
    away after the session)."""
    if session.status != "accepted":
        return UnitResult(
            session.serial, FAIL, _rejected(session), session_id=session.session_id, views=len(session.views)
        )
    try:
        art = solve(settings, _solve_request(session, request)).artifact
    except DatabaseUnreachableError as exc:  # the session is stored; its calibration is queued
        return _queued_line(
            queue_solved(settings, offline.spool(), session, request.model, session_stored=True),
            exc.message,
            _SYNC_HINT,
        )
    status = PASS if art.status == "accepted" else FAIL
    return UnitResult(
        session.serial,
        status,
        f"calibration v{art.version} {art.status}",
        session_id=session.session_id,
        version=art.version,
        rms_px=art.rms_px,
        views=len(session.views),
    )


def _queued_line(queued: Queued, why: str, hint: str) -> UnitResult:
    session, art = queued.session, queued.artifact
    what = _rejected(session) if art is None else f"calibration {art.status}"
    verdict = PASS if art is not None and art.status == "accepted" else FAIL
    return UnitResult(
        session.serial,
        QUEUED,
        f"{what}; queued as spool record {queued.seq}, its version comes when the store is back ({why})",
        hint,
        session.session_id,
        None,
        None if art is None else art.rms_px,
        len(session.views),
        verdict=verdict,
        spool_record=queued.seq,
    )


def _synced_line(unit: SyncedUnit) -> UnitResult:
    if unit.version is None:
        what = "its rejected capture session stored"
    else:
        what = f"stored as v{unit.version} {unit.status}{', active' if unit.active else ''}"
    already = " (it was in the store already)" if unit.already else ""
    return UnitResult(
        unit.serial,
        SYNCED,
        f"spool record {unit.seq}: {what}{already}",
        session_id=unit.session_id,
        version=unit.version,
        rms_px=unit.rms_px,
        views=unit.views,
        verdict=PASS if unit.status == "accepted" else FAIL,
        spool_record=unit.seq,
    )


def run_station(
    settings: Settings,
    request: StationRequest,
    serials: Iterable[str],
    report: Callable[[UnitResult], None],
    observer: Callable[[], CaptureObserver] = CaptureObserver,
) -> StationSummary:
    """Calibrate one unit per serial line until the lines end or Ctrl-C (see the module docstring).

    ``report(result)`` is called once per non-blank line, as soon as its unit is done; ``observer()``
    makes each unit's capture observer (the CLI's progress display).
    """
    check_request(request)
    summary = StationSummary()
    seen: dict[str, int] = {}
    units = 0
    lines: Iterator[str] = iter(serials)
    offline = _Offline(settings, request.spool)
    with (
        offline,
        _Interrupts() as interrupts,
        _sqlite_kept_open(settings),
        _early_numbers(settings, request) as early,
    ):
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
            units += 1
            result = _checked_serial(serial, seen)
            if result is None:
                try:
                    why_queue = offline.before_unit(lambda synced: _keep(summary, report, synced))
                    with observer() as display:
                        unit_observer = _UnitObserver(interrupts, display, early)
                        result = _unit(settings, request, serial, unit_observer, offline, why_queue)
                except KeyboardInterrupt:
                    during = (
                        "captured from the camera"
                        if request.camera is not None
                        else "awaited or detected"
                        if request.watch is not None
                        else "detected"
                    )
                    result = UnitResult(
                        serial,
                        CANCELLED,
                        f"cancelled (Ctrl-C) while its images were {during}; nothing was stored",
                        "scan the serial again to calibrate it",
                    )
                except CalibctlError as exc:
                    result = UnitResult(serial, ERROR, exc.message, exc.hint)
                if result.status in (PASS, FAIL, QUEUED):
                    seen[serial] = units
            after = None if result.last_image_at is None else time.time() - result.last_image_at
            result = replace(result, unit_s=time.perf_counter() - start, after_last_image_s=after)
            summary.units.append(result)
            report(result)
            if interrupts.pending:
                summary.interrupted = True
                break
    return summary


@contextlib.contextmanager
def _sqlite_kept_open(settings: Settings) -> Iterator[None]:
    """Hold a SQLite store open for the station's life. SQLite checkpoints its write-ahead log into the
    database and deletes it when the last connection to the file closes, and a unit closes the store twice
    (capture, solve): 4.7-24 ms a close, 0.05-0.09 ms with another connection open (the 2-core VM at load 9,
    a 20 KB insert before each). With this one open no unit's close is the last; SQLite still checkpoints as
    the log grows (every 1000 pages). A store that cannot be opened now (away, absent, out of date) is left
    alone: each unit opens it, or says why not, as before."""
    held = None
    if settings.db_url.startswith("sqlite"):
        with contextlib.suppress(CalibctlError):
            held = Store.open(settings.db_url, create=False)  # its migration check leaves a connection open
    try:
        yield
    finally:
        if held is not None:
            held.close()


def _keep(summary: StationSummary, report: Callable[[UnitResult], None], line: UnitResult) -> None:
    summary.units.append(line)
    report(line)


def _checked_serial(serial: str, seen: dict[str, int]) -> UnitResult | None:
    if not re.fullmatch(SERIAL_PATTERN, serial):
        shown = bounded.printable(serial)  # a scanner's escape sequences must not drive the terminal
        control = shown != serial
        return UnitResult(
            shown,
            ERROR,
            f"'{shown}' is not a serial"
            + (": it holds control characters (shown escaped, \\xNN)" if control else ""),
            "a serial is letters, digits and . _ : - (no spaces, no '@'); "
            + (
                "check the scanner's prefix and suffix settings (it sent escape sequences), then scan again"
                if control
                else "scan the label again"
            ),
        )
    if serial in seen:
        return UnitResult(
            serial,
            ERROR,
            f"{serial} was already calibrated in this run (unit {seen[serial]}); not calibrated again",
            "scan the next unit; to recalibrate this one, run calibctl calibrate",
        )
    return None
