"""``calibctl capture`` / ``calibrate`` / ``prune``: pictures -> a stored capture session with its gate
verdict.

A capture reads a folder of images (detected in parallel, every image gets an outcome) or a video /
live camera (each frame detected in turn and offered to ``core.capture.frame_select.FrameSelector``, which
keeps still frames that add coverage or tilt), checks that the registered board matches the board in
the pictures (``pattern_check``), evaluates the capture gates (``core.capture.gates``, thresholds from the
settings, so a station file can override them; then ``one_camera`` from ``core.capture.camera_split``, the
solve's two-camera test) and stores the session.

What is written, and when:
  * images first into the content-addressed image store (``Store.put_images``, retention
    ``settings.image_retention_days``): every readable image of a folder, ``IMAGE_BATCH`` images per
    transaction, on a thread of their own while the gates run (``image_writes``), and every kept frame of
    a video or camera encoded as PNG (from 2 jobs on, on the writer thread beside the selection) and stored,
    ``IMAGE_BATCH`` per transaction, once the stream is over. A crash after this point leaves only images,
    which are harmless (content-addressed, they expire);
  * then, once every image is durable, the whole session - per-image outcomes, per-view float64 corners with
  tilt, gate results with
    reason codes and hints, accepted/rejected - in one transaction (``Store.add_session``).
Nothing is written when the capture cannot run (exit 2): unknown board, unreadable source, no
readable image, a pattern that matches nothing or only part of the board.

Stopping a video or camera capture: when the gates pass and ``max_views`` views are kept (a camera
without ``max_views`` stops as soon as the gates pass; a video file without it is read to the end), on
``duration_s`` (video time for a file, wall time for a camera), at the end of a video file, or on Ctrl-C
- KeyboardInterrupt finishes the session with the views kept so far and says so (``cancel_on_interrupt``: the
station's unit is cancelled instead). A camera that stops delivering frames before one of these (unplugged, no
frame for ``capture_sources.CAMERA_FRAME_WAIT_S``) is an error naming the frames and views it gave (exit 2):
its views are no verdict on the lens, so no session is stored.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import re
import secrets
import threading
from collections import deque
from collections.abc import Generator, Iterator, Sequence
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import TracebackType
from typing import Protocol

import cv2
import numpy as np

from calibctl import __version__
from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.check import DistanceCheck
from calibctl.artifacts.common import SERIAL_PATTERN, utc_now
from calibctl.artifacts.session import CaptureSession, GateResult, MetricGauge, ViewCorners
from calibctl.artifacts.session import ImageOutcome as OutcomeRecord
from calibctl.config import Settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture import image_outcomes as outcomes_core
from calibctl.core.capture.arrivals import EarlyDetections
from calibctl.core.capture.camera_split import one_camera_gate
from calibctl.core.capture.detect import FOUND_INCONSISTENT, Detection, DetectorSettings
from calibctl.core.capture.frame_select import (
    KEPT,
    FrameDecision,
    FrameSelector,
    Probe,
    SelectionProgress,
    SelectorSettings,
    StreamDetector,
    probe_frame,
)
from calibctl.core.capture.gates import GateThresholds, evaluate_gates
from calibctl.core.capture.image_circle import (
    ImageCircle,
    accumulate_max,
    corners_inside,
    detect_image_circle,
    half_size,
    sized_half,
)
from calibctl.core.capture.projection_gate import (
    ADVISORY_GATES,
    cause_first,
    projection_gate,
    session_passed,
    solve_for_gate,
)
from calibctl.core.gate import GateResult as CoreGateResult
from calibctl.core.intrinsics.solve import DEFAULT_MODEL, IntrinsicsSolution
from calibctl.errors import InputError, NumericalError, UsageError
from calibctl.files import file_errors
from calibctl.store.repository import Store
from calibctl.workflows.board.boards import board_ref, board_spec
from calibctl.workflows.board.gauge_failures import board_failures
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.camera import pattern_check
from calibctl.workflows.camera.distance_gauge import ReferenceDistance, gauge_capture, gauge_model
from calibctl.workflows.camera.image_circles import checked_image_circle
from calibctl.workflows.camera.image_writes import ImageWrites
from calibctl.workflows.camera.solve import (
    MODEL_CHOICES,
    SolveOutcome,
    SolveRequest,
    checked_override,
    solve,
    station_region,
)
from calibctl.workflows.camera.verdict_lanes import verdict_lanes
from calibctl.workflows.store_admin import keys

SAMPLE_EVERY_FRAMES = 15  # frames kept aside to probe near patterns when no board is ever found
# a stream without --image-circle looks for the circle in its frames' maximum this often, so a live
# circular fisheye can stop once the cells inside the circle are covered (the corners are never lit)
CIRCLE_EVERY_FRAMES = 10
STREAM_AHEAD_PER_JOB = 2  # a stream's frames read and detected ahead of the one being selected, per job
IMAGE_BATCH = 16  # folder images per store transaction (one SQLite commit, one WAL fsync, per batch)
_FRAME_STATUS = {
    KEPT: "accepted",
    "no_board": "no_board",
    "blurred": "blurred",
    "near_duplicate": "near_duplicate",
    "moving": "skipped",
    "adds_nothing": "skipped",
}
_SERIAL_HINT = "a serial is letters, digits and . _ : - (no spaces, no '@'), e.g. CAM-0001"


@dataclass(frozen=True)
class CaptureRequest:
    serial: str
    board: str
    source: str
    max_views: int | None = None
    duration_s: float | None = None
    jobs: int | None = (
        None  # detection workers; None: settings.jobs (--jobs > CALIBCTL_JOBS > station file > cores)
    )
    image_circle: tuple[float, float, float] | None = (
        None  # --image-circle CX,CY,R px; None: found in the frames
    )
    reference_distance: ReferenceDistance | None = None  # with reference_source: the gauge (distance_gauge)
    reference_source: str | None = None
    # The lens model the gauge solves the session with, a MODELS name or "auto": calibrate's --model (the
    # lens the session will be solved with; see distance_gauge.gauge_model), k1k2 for a plain capture.
    gauge_model: str = DEFAULT_MODEL
    # The lens model the projection gate solves with: calibrate's --model (None, and for auto: the better fit
    # of k1k2 and fisheye, core.capture.projection_gate)
    lens_model: str | None = None
    # Ctrl-C during a video or camera stream: False finishes the session with the views kept (calibctl
    # capture);
    # True lets the KeyboardInterrupt through, nothing of the stream kept (the station cancels the unit)
    cancel_on_interrupt: bool = False


@dataclass(frozen=True)
class CaptureResult:
    session: CaptureSession
    stop_reason: str
    interrupted: bool
    images_stored: int
    image_dir: str
    ignored_files: tuple[str, ...] = ()
    distance: DistanceCheck | None = None  # --reference-distance: judged when the gates passed
    gauge_lens: str | None = None  # the lens model the distance was judged through (auto: the one it chose)

    @property
    def passed(self) -> bool:
        return self.session.status == "accepted" and (self.distance is None or self.distance.passed)

    def as_json(self) -> dict[str, object]:
        return {
            "session": self.session.model_dump(mode="json"),
            "passed": self.passed,
            "stop_reason": self.stop_reason,
            "interrupted": self.interrupted,
            "images_stored": self.images_stored,
            "image_dir": self.image_dir,
            "ignored_files": list(self.ignored_files),
            "distance": None if self.distance is None else self.distance.model_dump(mode="json"),
            "gauge_lens": self.gauge_lens,
        }


@dataclass(frozen=True)
class CalibrateResult:
    capture: CaptureResult
    solve: SolveOutcome | None


@dataclass(frozen=True)
class PruneResult:
    pruned: int
    image_dir: str
    now: dt.datetime


class CaptureObserver:
    """What a capture reports while it runs (the CLI draws a progress bar or a live view). No-ops here."""

    def folder_started(self, total: int) -> None: ...

    def image_done(self, done: int, total: int, name: str, status: str) -> None: ...

    def frame_done(self, decision: FrameDecision, progress: SelectionProgress, t_s: float) -> None: ...

    def session_built(self, session: CaptureSession) -> None:
        """The session and its gates are final; it is about to be written (the station starts its solve's
        numbers here, ``workflows.camera.solve.start_numbers``)."""

    def __enter__(self) -> CaptureObserver:  # a display to close when the capture ends (cli.live_view)
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        return None


class CaptureStore(Protocol):
    """What a capture needs of a store: ``Store``, or the station's spool while the store is away
    (``workflows.station.offline``)."""

    image_dir: Path

    def get_board(self, name: str, revision: int | None = None) -> BoardRevision: ...

    def put_image(self, data: bytes, *, retention_days: int) -> str: ...

    def put_images(self, images: Sequence[bytes], *, retention_days: int) -> list[str]: ...

    def add_session(self, session: CaptureSession) -> None: ...


@dataclass
class _Collected:
    """What a source produced, before the gates: outcomes, views with their image hashes."""

    outcomes: list[OutcomeRecord]
    views: list[tuple[BoardView, str | None]]
    image_size: tuple[int, int]
    stop_reason: str
    images_stored: int
    interrupted: bool = False
    ignored: list[str] = field(default_factory=list)
    max_gray: np.ndarray | None = None  # per-pixel maximum of the frames, reduced (core.capture.image_circle)
    writes: ImageWrites | None = None  # a folder's images, being stored beside the gates

    def images_durable(self) -> int:
        """Wait until every image is stored (the writes' error raised); how many were."""
        return self.images_stored + (0 if self.writes is None else self.writes.stored())


def core_thresholds(settings: Settings) -> GateThresholds:
    """The settings' gate thresholds (defaults < station file) as the core dataclass."""
    return GateThresholds(
        **settings.gates.model_dump(exclude={"projection_sigma_max_px", "projection_region"})
    )


def check_stream_stops(max_views: int | None, duration_s: float | None) -> None:
    """A video's or camera's stop rule (``--max-views``, ``--duration``) that cannot be met: a usage error."""
    if max_views is not None and max_views < 1:
        raise UsageError(f"--max-views must be 1 or more, got {max_views}")
    if duration_s is not None and not duration_s > 0:
        raise UsageError(f"--duration must be a positive number of seconds, got {duration_s:g}")


def _check_request(request: CaptureRequest) -> tuple[str, int | None]:
    if not re.fullmatch(SERIAL_PATTERN, request.serial):
        raise UsageError(f"'{request.serial}' is not a camera serial", _SERIAL_HINT)
    check_stream_stops(request.max_views, request.duration_s)
    if (request.reference_distance is None) != (request.reference_source is None):
        raise UsageError(
            "--reference-distance and --reference-source go together",
            "give the surveyed distance D+-S and the pictures taken with the board in that fixture",
        )
    gauge_model(request.gauge_model)  # an unknown name is a usage error before anything is read
    return board_ref(request.board)


def capture(
    settings: Settings,
    request: CaptureRequest,
    observer: CaptureObserver | None = None,
    *,
    store_session: bool = True,
    into: CaptureStore | None = None,
    detected: EarlyDetections | None = None,
) -> CaptureResult:
    """Run one capture and store its session (see the module docstring). Raises CalibctlError (exit 2)
    when it cannot run; a session that fails the gates is stored as rejected and returned.
    ``store_session=False``: the session is built and returned but not stored (a rig capture stores its
    members' sessions together with the rig session, in one transaction); its images are stored.
    ``into``: board, images and session go there instead of the configured store.
    ``detected``: a folder's images detected as they landed (the station's watch mode); each one still as it
    was then, with the same board, is not detected again (``classify_files(known=...)``)."""
    observer = observer or CaptureObserver()
    board_name, revision = _check_request(request)
    source = sources.resolve_source(request.source)
    if source.kind in sources.IMAGE_SETS and (
        request.max_views is not None or request.duration_s is not None
    ):
        raise UsageError(
            f"--max-views and --duration apply to video and camera sources, not to a {source.kind}",
            "a set of images is captured whole; leave out images you do not want",
        )
    started = utc_now()
    opened: AbstractContextManager[CaptureStore] = (
        Store.open(settings.db_url, trusted=keys.read_trust(settings)) if into is None else nullcontext(into)
    )
    # the pool's exit joins its thread: however capture() ends, no image write outlives it
    with (
        opened as store,
        ThreadPoolExecutor(max_workers=1, thread_name_prefix="calibctl-image-writes") as writer,
    ):
        board = store.get_board(board_name, revision)
        spec = board_spec(board)
        if source.kind in sources.IMAGE_SETS:
            got = _capture_images(
                store,
                settings,
                spec,
                board,
                source,
                request.jobs or settings.jobs,
                observer,
                writer,
                None if detected is None else detected.for_spec(spec, sized_half),
            )
        else:
            got = _capture_stream(store, settings, spec, board, source, request, observer, writer)
        try:
            session = _build_session(settings, request, board, spec, source, got, started)
            distance = lens = None
            if (
                request.reference_distance is not None
                and request.reference_source is not None
                and session.status == "accepted"
                and session.image_size is not None
            ):
                distance, lens = gauge_capture(
                    request.reference_distance,
                    request.reference_source,
                    spec,
                    board.ref,
                    session.views,
                    session.image_size,
                    request.gauge_model,
                    request.jobs or settings.jobs,
                )
                # the session carries the verdict: a failed gauge stops its solve (workflows.camera.solve)
                session = session.model_copy(
                    update={
                        "metric_gauge": MetricGauge(
                            distance=distance, lens_model=lens, reference_source=request.reference_source
                        )
                    }
                )
        except BaseException as failure:
            if got.writes is not None:
                got.writes.after(failure)  # a failure of the writes, met first in the sequential order, wins
            raise
        observer.session_built(session)
        stored = got.images_durable()  # before anything names the images
        if store_session:
            store.add_session(session)
        return CaptureResult(
            session,
            got.stop_reason,
            got.interrupted,
            stored,
            str(store.image_dir),
            tuple(got.ignored),
            distance,
            lens,
        )


def _record(o: outcomes_core.ImageOutcome) -> OutcomeRecord:
    return OutcomeRecord(
        name=o.name,
        status=o.status,
        reason=o.reason or None,
        sha256=o.sha256 or None,
        image_size=o.image_size,
        corners_found=0 if o.corner_ids is None else len(o.corner_ids),
    )


def refuse_another_pattern(
    spec: BoardSpec,
    board_ref: str,
    board_name: str,
    where: str,
    readable: list[outcomes_core.ImageOutcome],
    given: str | None = None,
) -> None:
    """InputError (exit 2) when the readable pictures show no board of ``spec`` or a larger one
    (``pattern_check``: the error names the board that is visible); ``given``: the options that named the
    pattern when no board is registered (e.g. "--cols/--rows")."""
    with_board = [o for o in readable if o.corner_ids is not None]
    if not with_board:
        raise pattern_check.nothing_found_error(
            spec, board_ref, board_name, where, len(readable), _load_samples(readable), given=given
        )
    accepted = [o for o in readable if o.accepted]
    # one view or none cannot show a larger board, the other images can: a 7x10 board registered as 9x6
    # shows a 9x6 part of itself in a stray image and nothing in the rest
    probed = next(
        (group for group in (accepted, with_board) if len(group) >= pattern_check.LARGER_MIN_HITS), readable
    )
    larger = pattern_check.larger_board_error(
        spec,
        board_ref,
        board_name,
        _load_samples(probed),
        {o.name: o.corners_px for o in probed if o.corners_px is not None},
        given=given,
    )
    if larger is not None:
        raise larger


def _load_samples(outcomes: list[outcomes_core.ImageOutcome]) -> list[pattern_check.Sample]:
    picks = pattern_check.spread([(o.name, o.path) for o in outcomes], pattern_check.PROBE_IMAGES)
    samples = []
    for name, path in picks:
        gray = outcomes_core.read_gray(str(path))
        if (
            gray is not None and min(gray.shape[:2]) >= outcomes_core.MIN_IMAGE_SIDE_PX
        ):  # probes need a picture
            samples.append((name, gray))
    return samples


class _MaxPicture:
    """The per-pixel maximum (``accumulate_max``) of a folder's images at half size, one per image size,
    filled from the half-size copies the detection workers make of the image they have just decoded
    (``sized_half``): no second decode of every file (it cost 175 ms of a 20-image 1280x960 PNG capture,
    on one thread). Half size is enough to find an image circle."""

    def __init__(self) -> None:
        self._by_size: dict[tuple[int, int], np.ndarray] = {}

    def add(self, summary: object) -> None:
        """``summary``: ``sized_half`` of one decoded image (called in the capturing thread)."""
        assert isinstance(summary, tuple)
        size: tuple[int, int] = summary[0]
        self._by_size[size] = accumulate_max(self._by_size.get(size), summary[1])

    def of_size(self, size: tuple[int, int]) -> np.ndarray | None:
        return self._by_size.get(size)


def _capture_images(
    store: CaptureStore,
    settings: Settings,
    spec: BoardSpec,
    board: BoardRevision,
    source: sources.SourceSpec,
    workers: int,
    observer: CaptureObserver,
    writer: Executor,
    known: outcomes_core.KnownCallback | None = None,
) -> _Collected:
    """Detect a folder's images (``known``: outcomes detected earlier, e.g. by a station's watch) and start
    storing the readable ones on ``writer`` (``image_writes``)."""
    where = source.label
    with file_errors(f"read the source {source.kind}", where):
        images = sources.select_images(source)
    observer.folder_started(len(images.paths))
    picture = _MaxPicture()
    with sources.quiet_opencv():  # a truncated file is reported as an outcome, not as a decoder warning
        found = outcomes_core.classify_files(
            images.paths,
            spec,
            workers=workers,
            progress=lambda done, total, o: observer.image_done(done, total, o.name, o.status),
            summarize=sized_half,
            on_summary=picture.add,
            known=known,
        )
    found = [replace(o, name=name) for o, name in zip(found, images.names, strict=True)]
    mixed = sources.mixed_sizes_error(
        source, {o.name: o.image_size for o in found if o.image_size is not None}
    )
    if mixed is not None:
        raise mixed
    results = outcomes_core.finalize_session(found)
    readable = [o for o in results if o.status != outcomes_core.UNREADABLE]
    if not readable:
        problems = "\n".join(f"  {o.name}: {o.reason}" for o in results)
        raise InputError(
            f"none of the {len(results)} image files in {where} could be read; nothing was stored:\n"
            f"{problems}",
            "re-copy the images from the camera; they are truncated or not images",
        )
    refuse_another_pattern(spec, board.ref, board.name, f"images in {where}", readable)
    accepted = [o for o in results if o.accepted]
    writes = ImageWrites(writer, lambda stop: _store_images(store, settings, readable, where, stop))
    size = outcomes_core.session_image_size(results)
    assert size is not None  # there are readable images
    views: list[tuple[BoardView, str | None]] = [
        (BoardView(o.name, o.corner_ids, o.corners_px), o.sha256)  # type: ignore[arg-type]
        for o in accepted
    ]
    return _Collected(
        [_record(o) for o in results],
        views,
        size,
        f"every image {'in the folder' if source.kind == sources.FOLDER else 'of the ' + source.kind} was "
        "examined "
        f"({len(results)})",
        0,
        ignored=images.ignored,
        max_gray=picture.of_size(size),
        writes=writes,
    )


def _store_images(
    store: CaptureStore,
    settings: Settings,
    readable: list[outcomes_core.ImageOutcome],
    where: str,
    stop: threading.Event,
) -> int:
    """Store ``readable``'s files, ``IMAGE_BATCH`` per transaction, until done or ``stop`` is set between two
    batches; how many were stored. Runs on the capture's writer thread (``image_writes``)."""
    stored = 0
    for start in range(0, len(readable), IMAGE_BATCH):  # one transaction per batch, a bounded batch in memory
        if stop.is_set():
            break
        batch = readable[start : start + IMAGE_BATCH]
        with file_errors("read the images in", where):
            image_bytes = [Path(o.path).read_bytes() for o in batch]
        shas = store.put_images(image_bytes, retention_days=settings.image_retention_days)
        for o, sha in zip(batch, shas, strict=True):
            if sha != o.sha256:
                raise InputError(
                    f"{o.path} changed while it was being captured; nothing was stored",
                    "capture again from a folder nothing else writes to",
                )
        stored += len(batch)
    return stored


class _StreamState:
    """What a video or camera capture accumulates, frame by frame."""

    def __init__(
        self,
        store: CaptureStore,
        settings: Settings,
        spec: BoardSpec,
        image_circle: tuple[float, float, float] | None = None,
        encoder: Executor | None = None,
    ) -> None:
        self.store, self.settings, self.spec = store, settings, spec
        self.encoder = (
            encoder  # encodes the kept frames as PNG beside the selection (None: in the selecting thread)
        )
        self.image_circle = image_circle  # a given --image-circle, checked against the first frame
        self.selector: FrameSelector | None = None
        self.detector = StreamDetector(spec)
        self.progress: SelectionProgress | None = None
        self.outcomes: list[OutcomeRecord] = []
        self.shas: dict[str, str] = {}
        self.no_board_samples: deque[pattern_check.Sample] = deque(maxlen=pattern_check.PROBE_IMAGES)
        self.kept_samples: list[pattern_check.Sample] = []
        self.kept_corners_px: dict[str, np.ndarray] = {}  # detected corners of the kept samples, by label
        self.boards_seen = self.stored = 0
        self._kept_png: list[
            tuple[str, int, Future[bytes] | bytes]
        ] = []  # (label, outcome index, PNG) to store
        self.max_gray: np.ndarray | None = None
        self.frames_seen = 0

    def _look_for_circle(self, size: tuple[int, int]) -> None:
        """The circle the frames so far show (None: the corners were lit, no circle); the live gates count
        coverage inside it from now on. It may grow as more of the scene is lit; the session's own circle
        is found again from all the frames when it is stored."""
        assert self.selector is not None and self.max_gray is not None
        found = detect_image_circle(self.max_gray, size)
        if found != self.selector.settings.image_circle:
            self.selector.settings = replace(self.selector.settings, image_circle=found)
            if self.selector.kept:
                self.progress = self.selector.progress()

    def begin(self, frame: sources.Frame) -> tuple[np.ndarray, tuple[int, int], bool]:
        """A frame's gray image and size, and whether it has the stream's size (the first frame sets it).
        Called in frame order, possibly ahead of ``finish`` of the frames before it."""
        gray = sources.to_gray(frame.image)
        size = (int(gray.shape[1]), int(gray.shape[0]))
        if self.selector is None:
            thresholds = core_thresholds(self.settings)
            circle = None if self.image_circle is None else checked_image_circle(self.image_circle, size)
            self.selector = FrameSelector(
                self.spec, size, SelectorSettings(thresholds=thresholds, image_circle=circle)
            )
            self.progress = self.selector.progress()
        return gray, size, size == self.selector.image_size

    def take(self, frame: sources.Frame) -> FrameDecision | None:
        """Detect, select and (when kept) store one frame; None when it has the wrong size."""
        gray, size, right_size = self.begin(frame)
        return self.finish(frame, gray, size, self.detector.detect(gray) if right_size else None)

    def finish(
        self,
        frame: sources.Frame,
        gray: np.ndarray,
        size: tuple[int, int],
        found: tuple[Detection | None, str] | None,
        half: np.ndarray | None = None,
    ) -> FrameDecision | None:
        """Select and (when kept) store one frame, in frame order, given its detection (``found``: None for a
        frame of the wrong size) and ``half_size(gray)`` when a worker made it; None when it has the wrong
        size."""
        assert self.selector is not None  # begin() ran
        if found is None:
            w, h = self.selector.image_size
            self.outcomes.append(
                OutcomeRecord(
                    name=frame.label,
                    status="wrong_size",
                    image_size=size,
                    reason=(f"frame is {size[0]}x{size[1]} but the stream's frames are {w}x{h}"),
                )
            )
            return None
        self.max_gray = accumulate_max(self.max_gray, half_size(gray) if half is None else half)
        self.frames_seen += 1
        if self.image_circle is None and self.frames_seen % CIRCLE_EVERY_FRAMES == 0:
            self._look_for_circle(size)
        detection, why = found
        if detection is None:
            if frame.index % SAMPLE_EVERY_FRAMES == 0:
                self.no_board_samples.append((frame.label, gray))
        else:
            self.boards_seen += 1
        decision = self.selector.offer(frame.index, detection, frame.label)
        if decision.kept:  # its PNG is stored with the others once the stream is over (store_kept)
            png = (
                sources.encode_png(frame.image)
                if self.encoder is None
                else self.encoder.submit(sources.encode_png, frame.image)
            )
            self._kept_png.append((frame.label, len(self.outcomes), png))
            if len(self.kept_samples) < pattern_check.PROBE_IMAGES:
                self.kept_samples.append((frame.label, gray))
                if detection is not None:  # always, a kept frame has a board
                    self.kept_corners_px[frame.label] = detection.corners_px
            self.progress = self.selector.progress()
        status = (
            "bad_grid" if detection is None and FOUND_INCONSISTENT in why else _FRAME_STATUS[decision.status]
        )
        self.outcomes.append(
            OutcomeRecord(
                name=frame.label,
                status=status,
                reason=None if decision.kept else (why or decision.reason),
                image_size=size,
                corners_found=0 if detection is None else len(detection.corner_ids),
            )
        )
        return decision

    def store_kept(self) -> None:
        """Store the kept frames' PNGs, ``IMAGE_BATCH`` per transaction, and name them in their outcomes."""
        for start in range(0, len(self._kept_png), IMAGE_BATCH):
            batch = self._kept_png[start : start + IMAGE_BATCH]
            pngs = [png if isinstance(png, bytes) else png.result() for _, _, png in batch]
            shas = self.store.put_images(pngs, retention_days=self.settings.image_retention_days)
            for (label, index, _), sha in zip(batch, shas, strict=True):
                self.shas[label] = sha
                self.outcomes[index] = self.outcomes[index].model_copy(update={"sha256": sha})
            self.stored += len(batch)
        self._kept_png = []


def _probe_and_half(
    gray: np.ndarray, spec: BoardSpec, settings: DetectorSettings | None, forced: bool
) -> tuple[Probe, np.ndarray]:
    """A stream frame's work that does not depend on the frames before it, for a worker thread."""
    return probe_frame(gray, spec, settings, forced), half_size(gray)


def _detected_frames(
    state: _StreamState, frames: Iterator[sources.Frame], jobs: int
) -> Generator[tuple[sources.Frame, FrameDecision | None], None, None]:
    """Each frame with its decision, in order (``state.take``), detected on ``jobs`` threads.

    With more than one job the frames are detected ahead: up to ``STREAM_AHEAD_PER_JOB`` x jobs frames are
    read and probed on the threads (``frame_select.probe_frame`` and the half-size copy for the frames'
    maximum: OpenCV releases the GIL) while the frames before them are settled and offered in order
    (``StreamDetector.settle``, ``finish``), so every frame gets the detection, and the session the decisions,
    of the one-thread run. The frames read ahead of a stop are dropped unrecorded, as the one-thread run never
    read them.
    """
    if jobs <= 1:
        for frame in frames:
            yield frame, state.take(frame)
        return
    pool = ThreadPoolExecutor(max_workers=jobs, thread_name_prefix="calibctl-stream-detect")
    ahead: deque[
        tuple[sources.Frame, np.ndarray, tuple[int, int], bool, Future[tuple[Probe, np.ndarray]] | None]
    ] = deque()
    more = True
    try:
        while True:
            while more and len(ahead) < STREAM_AHEAD_PER_JOB * jobs:
                read = next(frames, None)
                if read is None:
                    more = False
                    break
                gray, size, right_size = state.begin(read)
                if not right_size:
                    ahead.append((read, gray, size, False, None))
                    continue
                forced = state.detector.next_forced()
                ahead.append(
                    (
                        read,
                        gray,
                        size,
                        forced,
                        pool.submit(_probe_and_half, gray, state.spec, state.detector.settings, forced),
                    )
                )
            if not ahead:
                return
            frame, gray, size, forced, work = ahead.popleft()
            if work is None:  # the wrong size: no detection
                yield frame, state.finish(frame, gray, size, None)
                continue
            probe, half = work.result()
            yield frame, state.finish(frame, gray, size, state.detector.settle(gray, forced, probe), half)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _capture_stream(
    store: CaptureStore,
    settings: Settings,
    spec: BoardSpec,
    board: BoardRevision,
    source: sources.SourceSpec,
    request: CaptureRequest,
    observer: CaptureObserver,
    writer: Executor,
) -> _Collected:
    """A video's or camera's frames selected into views; from 2 jobs on the kept frames are encoded as PNG on
    the capture's ``writer`` thread (the one a folder's images are stored on) beside the selection."""
    jobs = request.jobs or settings.jobs
    stream = sources.open_stream(source)
    is_file = source.kind == sources.VIDEO
    target = request.max_views if request.max_views is not None else (None if is_file else 0)
    state = _StreamState(store, settings, spec, request.image_circle, writer if jobs > 1 else None)
    interrupted = False
    stop = "end of the video" if is_file else None  # a camera ends by a stop rule, never by itself
    reached: list[bool] = []  # the frames from --duration on are not read further, nor detected

    def until_duration(frames: Iterator[sources.Frame]) -> Iterator[sources.Frame]:
        for frame in frames:
            if request.duration_s is not None and frame.t_s >= request.duration_s:
                reached.append(True)
                return
            yield frame

    # a video file's frames are decoded on a thread of their own beside the detection (a camera's already are)
    read: AbstractContextManager[Iterator[sources.Frame]] = (
        sources.read_ahead(stream.frames(), STREAM_AHEAD_PER_JOB * jobs)
        if is_file and jobs > 1
        else nullcontext(stream.frames())
    )
    try:
        with (
            read as frames,
            contextlib.closing(_detected_frames(state, until_duration(frames), jobs)) as decided,
        ):
            for frame, decision in decided:
                progress = state.progress
                if decision is None or progress is None:
                    continue
                observer.frame_done(decision, progress, frame.t_s)
                if (
                    decision.kept
                    and target is not None
                    and progress.report.passed
                    and progress.n_views >= target
                ):
                    stop = f"the gates passed with {progress.n_views} views" + (
                        f" (--max-views {target})" if request.max_views is not None else ""
                    )
                    break
            else:
                if reached:
                    stop = f"--duration {request.duration_s:g} s reached"
    except KeyboardInterrupt:
        if request.cancel_on_interrupt:
            raise
        interrupted, stop = True, "interrupted (Ctrl-C)"
    finally:
        stream.close()
    if state.selector is None:
        raise InputError(
            f"no frame arrived from {source.label}; nothing was stored",
            "check that the camera streams (e.g. with another viewer) and try again",
        )
    if stop is None:
        raise _camera_lost(source, state, request)
    if state.boards_seen == 0:
        raise pattern_check.nothing_found_error(
            spec,
            board.ref,
            board.name,
            f"frames of {source.label}",
            len(state.outcomes),
            list(state.no_board_samples),
        )
    samples = state.kept_samples
    if (
        len(samples) < pattern_check.LARGER_MIN_HITS
    ):  # as for a folder: look at the frames without the pattern
        samples = [*samples, *state.no_board_samples]
    larger = pattern_check.larger_board_error(spec, board.ref, board.name, samples, state.kept_corners_px)
    if larger is not None:
        raise larger
    state.store_kept()  # the kept frames' images, before anything names them
    views = [(view, state.shas.get(view.name)) for view in state.selector.kept]
    if interrupted:
        stop += f"; the session was finished with the {len(views)} view(s) kept"
    return _Collected(
        state.outcomes,
        views,
        state.selector.image_size,
        stop,
        state.stored,
        interrupted,
        max_gray=state.max_gray,
    )


def _camera_lost(source: sources.SourceSpec, state: _StreamState, request: CaptureRequest) -> InputError:
    """A camera that stopped before a stop rule (unplugged, its driver gone, no frame for
    ``CAMERA_FRAME_WAIT_S``): the views it left are no verdict on the lens, so no session is made."""
    kept = 0 if state.selector is None else len(state.selector.kept)
    progress = state.progress
    if progress is not None and not progress.report.passed:
        short = "the gates had not passed"
    else:
        short = f"{kept} of the {request.max_views} views asked for"
    return InputError(
        f"{source.label} stopped delivering frames after {len(state.outcomes)} frame(s), {kept} view(s) "
        f"kept ({short}): unplugged, or taken by another program?; no session was stored",
        "check the camera's cable and that nothing else holds the device, then capture again",
    )


def _gate_records(gates: Sequence[CoreGateResult]) -> list[GateResult]:
    decided = any(g.gate == "projection" for g in gates)  # then tilt and coverage are guidance
    return [
        GateResult(
            gate=g.gate,
            passed=g.passed,
            value=float(g.value),
            threshold=float(g.threshold),
            reason=g.reason,
            hint=g.hint,
            detail=dict(g.detail),
            advisory=decided and g.gate in ADVISORY_GATES,
        )
        for g in gates
    ]


def _projection(
    settings: Settings,
    request: CaptureRequest,
    views: Sequence[BoardView],
    model_points: np.ndarray,
    image_size: tuple[int, int],
    circle: ImageCircle | None,
) -> CoreGateResult:
    """The decisive gate (core.capture.projection_gate) over the station's region; exit 2 for a bad region."""
    region = station_region(settings, image_size, None if circle is None else circle.as_tuple())
    obj = [model_points[np.asarray(v.corner_ids)] for v in views]
    px = [np.asarray(v.corners_px, np.float64) for v in views]
    try:
        solution: IntrinsicsSolution | NumericalError = solve_for_gate(
            obj, px, image_size, request.lens_model
        )
    except NumericalError as exc:
        solution = exc
    limit = settings.gates.projection_sigma_max_px
    gate = projection_gate(solution, image_size, region, limit)
    return cause_first(gate, solution, obj, px, image_size, region, limit)


def _build_session(
    settings: Settings,
    request: CaptureRequest,
    board: BoardRevision,
    spec: BoardSpec,
    source: sources.SourceSpec,
    got: _Collected,
    started: dt.datetime,
) -> CaptureSession:
    board_views = [view for view, _ in got.views]
    circle = session_image_circle(request.image_circle, got, board_views)
    model_points = spec.object_points()
    with verdict_lanes(request.jobs or settings.jobs) as lanes:
        # Same test as the solve's (lint rule one-camera), while the operator still holds the board; its
        # solves are independent of the other gates', so it runs on another lane beside them (verdict_lanes)
        two_cameras = lanes.start(
            lambda: one_camera_gate(
                [model_points[np.asarray(v.corner_ids)] for v in board_views],
                [np.asarray(v.corners_px, np.float64) for v in board_views],
                [v.name for v in board_views],
                got.image_size,
                lanes=lanes,
            )
        )
        try:
            report = evaluate_gates(
                board_views, model_points, got.image_size, core_thresholds(settings), image_circle=circle
            )
            # not hopeless: judge the prediction
            judge = all(g.passed for g in report.gates if g.gate in ("observability", "views"))
            projection = (
                _projection(settings, request, board_views, model_points, got.image_size, circle)
                if judge
                else None
            )
        except BaseException:
            two_cameras.settle()
            raise
        gates = [*report.gates, two_cameras.result(), *([] if projection is None else [projection])]
    geometry = {g.name: g for g in report.views}
    views = []
    for view, sha in got.views:
        g = geometry.get(view.name)
        views.append(
            ViewCorners(
                name=view.name,
                image_sha256=sha,
                corner_ids=[int(i) for i in view.corner_ids],
                corners_px=[(float(u), float(v)) for u, v in np.asarray(view.corners_px, np.float64)],
                tilt_deg=None if g is None else float(g.tilt_deg),
                tilt_direction=None if g is None else g.direction_name,
            )
        )
    return CaptureSession(
        session_id=secrets.token_hex(6),
        serial=request.serial,
        board=board,
        source=source.recorded,
        source_kind=source.kind,
        station=settings.station,
        operator=settings.operator,
        started_at=started,
        finished_at=utc_now(),
        image_size=got.image_size,
        status="accepted" if session_passed(gates) else "rejected",
        gates=_gate_records(gates),
        outcomes=got.outcomes,
        views=views,
        calibctl_version=__version__,
        opencv_version=cv2.__version__,
    )


def session_image_circle(
    given: tuple[float, float, float] | None, got: _Collected, views: list[BoardView]
) -> ImageCircle | None:
    """The given circle (checked against the image and the board), else the one found in the frames."""
    if given is None:
        return None if got.max_gray is None else detect_image_circle(got.max_gray, got.image_size)
    circle = checked_image_circle(given, got.image_size)
    corners = [np.asarray(v.corners_px, np.float64).reshape(-1, 2) for v in views]
    if corners and not any(corners_inside(px, circle).any() for px in corners):
        nearest = min(
            float(np.hypot(px[:, 0] - circle.cx_px, px[:, 1] - circle.cy_px).min()) for px in corners
        )
        raise InputError(
            f"the board never enters the image circle ({circle.describe()}): in {len(corners)} "
            f"view(s) the nearest corner is {nearest:.1f} px from its centre, "
            f"{nearest - circle.radius_px:.1f} px outside it; no session was stored",
            "check --image-circle against the frames (its centre and radius in pixels)",
        )
    return circle


def calibrate(
    settings: Settings,
    request: CaptureRequest,
    model: str = DEFAULT_MODEL,
    activate: bool = True,
    drop_outliers: bool = False,
    observer: CaptureObserver | None = None,
    override_gauge: str | None = None,
) -> CalibrateResult:
    """Capture, then - when the gates pass - solve the new session (``workflows.camera.solve``). A failed
    distance gauge stops it too, unless ``override_gauge`` gives the reason (recorded in the calibration)."""
    if model not in MODEL_CHOICES:
        raise UsageError(f"unknown model '{model}'", f"choose one of {', '.join(MODEL_CHOICES)}")
    checked_override(override_gauge)
    board_failed = override_gauge is not None and _board_has_failed_gauge(settings, request.board)
    if override_gauge is not None and request.reference_distance is None and not board_failed:
        raise UsageError(
            f"--override-gauge overrides a failed metric gauge: none is asked for and board {request.board} "
            "has no failed one",
            "give --reference-distance and --reference-source, or leave --override-gauge out",
        )
    # the gauge at capture judges the board distance through the lens this session is solved with
    captured = capture(
        settings,
        replace(request, gauge_model=gauge_model(model), lens_model=None if model == "auto" else model),
        observer,
    )
    gauge_only = captured.session.status == "accepted" and override_gauge is not None
    if not captured.passed and not gauge_only:
        return CalibrateResult(captured, None)
    solved = solve(
        settings,
        SolveRequest(
            session_id=captured.session.session_id,
            model=model,
            activate=activate,
            drop_outliers=drop_outliers,
            override_gauge=override_gauge if board_failed or not captured.passed else None,
        ),
    )
    return CalibrateResult(captured, solved)


def _board_has_failed_gauge(settings: Settings, board: str) -> bool:
    """Whether the board revision ``board`` (NAME or NAME@REV) has a failed metric gauge in the store."""
    name, revision = board_ref(board)
    with Store.open(settings.db_url) as store:
        return bool(board_failures(store, store.get_board(name, revision).ref))


def parse_now(text: str) -> dt.datetime:
    """ISO 8601 date or date-time; a value without a zone is UTC."""
    try:
        when = dt.datetime.fromisoformat(text.strip())
    except ValueError as exc:
        raise UsageError(
            f"--now '{text}' is not an ISO 8601 time", "e.g. 2026-04-30 or 2026-04-30T12:00:00Z"
        ) from exc
    return when.replace(tzinfo=dt.UTC) if when.tzinfo is None else when.astimezone(dt.UTC)


def prune(settings: Settings, now: dt.datetime | None = None) -> PruneResult:
    """Delete images whose retention has expired (never corners, sessions or calibrations)."""
    when = now or utc_now()
    # Maintenance of an existing store: a mistyped --db is exit 2 naming the path, never a new empty store.
    with Store.open(settings.db_url, create=False) as store:
        return PruneResult(store.prune_images(when), str(store.image_dir), when)


def classify_photos(
    paths: Sequence[str | Path], spec: BoardSpec, workers: int | None = None
) -> tuple[list[outcomes_core.ImageOutcome], np.ndarray | None]:
    """Every photo's outcome as a folder capture classifies them (``finalize_session`` included), and the
    per-pixel maximum of the photos at half size, which a circular fisheye's image circle is found in (None:
    no image)."""
    picture = _MaxPicture()
    with sources.quiet_opencv():
        found = outcomes_core.classify_files(
            paths, spec, workers=workers, summarize=sized_half, on_summary=picture.add
        )
    results = outcomes_core.finalize_session(found)
    size = outcomes_core.session_image_size(results)
    return results, None if size is None else picture.of_size(size)


def photos_session(
    settings: Settings,
    request: CaptureRequest,
    board: BoardRevision,
    spec: BoardSpec,
    source: sources.SourceSpec,
    outcomes: Sequence[outcomes_core.ImageOutcome],
    max_gray: np.ndarray | None = None,
) -> CaptureSession:
    """The session a folder ``capture`` builds from photos already classified (``classify_photos``), its gates
    and verdict included, in memory: nothing is stored. ``rig solve-folders`` judges each member by it."""
    size = outcomes_core.session_image_size(list(outcomes))
    if size is None:
        raise InputError(f"none of the {len(outcomes)} photos of {source.label} could be read")
    views: list[tuple[BoardView, str | None]] = [
        (BoardView(o.name, o.corner_ids, o.corners_px), o.sha256)  # type: ignore[arg-type]
        for o in outcomes
        if o.accepted and o.corner_ids is not None
    ]
    got = _Collected(
        [_record(o) for o in outcomes],
        views,
        size,
        f"every photo of {source.label} was examined",
        0,
        max_gray=max_gray,
    )
    return _build_session(settings, request, board, spec, source, got, utc_now())
