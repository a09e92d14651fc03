"""Per-image outcomes of a capture session, and a parallel runner over a folder of images.

Every image gets exactly one outcome, decided in this order:

    unreadable      the bytes do not decode as an image
    wrong_size      not the session's image size (the most common size among readable images, ties to
                    the first file in name order, unless the caller states the size)
    no_board        no detector found a board (reason from ``detect``)
    bad_grid        a detector found the board but no refinement gives a consistent corner grid
    blurred         the board's edges are wider than ``DetectorSettings.blur_max_edge_px``
    near_duplicate  its corners are within ``NEAR_DUPLICATE_FRAC`` x the image diagonal (mean over
                    shared corners) of an earlier accepted image: it adds no geometry
    accepted

Detection runs per file, in parallel (``classify_files``: worker processes from ``core.capture.worker_pool``,
handed a few files per task (``task_chunks``), or threads, see ``choose_executor``); the size and
near-duplicate decisions need the whole session and run afterwards, in file-name order
(``finalize_session``), so results are deterministic whatever order the workers finish in.
"""

from __future__ import annotations

import contextlib
import hashlib
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import worker_pool
from calibctl.core.capture.detect import FOUND_INCONSISTENT, Detection, DetectorSettings, detect_board
from calibctl.core.intrinsics.solution import single_threaded_opencv
from calibctl.errors import WorkerDiedError, named_list

ACCEPTED = "accepted"
NO_BOARD = "no_board"
BAD_GRID = "bad_grid"
BLURRED = "blurred"
NEAR_DUPLICATE = "near_duplicate"
WRONG_SIZE = "wrong_size"
UNREADABLE = "unreadable"
STATUSES = (ACCEPTED, NO_BOARD, BAD_GRID, BLURRED, NEAR_DUPLICATE, WRONG_SIZE, UNREADABLE)

MIN_IMAGE_SIDE_PX = 32  # a board of 2x2 inner corners needs more; 1x1 and 2x3 images divided by zero
NEAR_DUPLICATE_FRAC = 0.01  # 8 px on a 640x480 image, 14.7 px on 1280x720
EXECUTORS = ("auto", "thread", "process")
DEFAULT_EXECUTOR = "auto"
PROCESS_MIN_FILES = 32  # "auto" detects this many files or more on processes (choose_executor)
CHUNK_MAX_FILES = (
    8  # files per process-pool task at most (task_chunks): 8 x ~17 ms at 1280x960 between reports
)
CHUNK_SHARE = (
    2  # a task takes at most 1/(CHUNK_SHARE x workers) of the files left, so the last tasks are single files
)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")

ProgressCallback = Callable[[int, int, "ImageOutcome"], None]
DecodedCallback = Callable[[np.ndarray], None]
Summarize = Callable[[np.ndarray], object]  # applied to a decoded image in the worker; picklable
SummaryCallback = Callable[[object], None]
KnownCallback = Callable[[Path], "tuple[ImageOutcome, object] | None"]  # an outcome detected earlier, or None


@dataclass(frozen=True)
class ImageOutcome:
    """What happened to one image.

    Attributes:
        name: file name (or frame label); path: where it was read from.
        status: one of STATUSES; reason: why, in words ("" when accepted).
        image_size: (width, height) px, None when unreadable.
        sha256: hex digest of the file bytes.
        corner_ids: (N,) int64 and corners_px: (N, 2) float64 when a board was found (kept for
            blurred / near-duplicate / wrong-size images too, so reports can show them).
        method: detector that found the board; edge_width_px: blur measure; elapsed_s: detection time.
    """

    name: str
    path: str
    status: str
    reason: str
    image_size: tuple[int, int] | None
    sha256: str
    corner_ids: np.ndarray | None = None
    corners_px: np.ndarray | None = None
    method: str | None = None
    edge_width_px: float | None = None
    elapsed_s: float = 0.0

    @property
    def accepted(self) -> bool:
        return self.status == ACCEPTED


def list_images(folder: Path) -> list[Path]:
    """Image files directly in ``folder``, in file-name order."""
    return sorted(
        (p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES),
        key=lambda p: p.name,
    )


def classify_array(
    name: str,
    path: str,
    gray: np.ndarray,
    sha256: str,
    spec: BoardSpec,
    settings: DetectorSettings | None = None,
) -> ImageOutcome:
    """Detect and blur-check one decoded (H, W) uint8 image; the session decisions come later."""
    settings = settings or DetectorSettings()
    size = (int(gray.shape[1]), int(gray.shape[0]))
    if min(size) < MIN_IMAGE_SIDE_PX:  # no board fits; the detectors' arithmetic assumes some pixels
        return ImageOutcome(
            name,
            path,
            NO_BOARD,
            f"the image is only {size[0]}x{size[1]} px, too small to hold a board",
            size,
            sha256,
        )
    start = time.perf_counter()
    detection, why = detect_board(gray, spec, settings)
    elapsed = time.perf_counter() - start
    if detection is None:
        status = BAD_GRID if FOUND_INCONSISTENT in why else NO_BOARD
        return ImageOutcome(name, path, status, why, size, sha256, elapsed_s=elapsed)
    status, reason = ACCEPTED, ""
    width = detection.edge_width_px
    if width is not None and width > settings.blur_max_edge_px:
        status = BLURRED
        reason = (
            f"board edges are {width:.1f} px wide (limit {settings.blur_max_edge_px:.1f} px): "
            f"out of focus or moving"
        )
    return _with_detection(
        ImageOutcome(name, path, status, reason, size, sha256, elapsed_s=elapsed), detection
    )


def _with_detection(outcome: ImageOutcome, detection: Detection) -> ImageOutcome:
    return replace(
        outcome,
        corner_ids=detection.corner_ids,
        corners_px=detection.corners_px,
        method=detection.method,
        edge_width_px=detection.edge_width_px,
    )


def decode_gray(data: bytes) -> np.ndarray | None:
    """(H, W) uint8 from encoded image bytes; None when they are not a decodable image. Always from bytes
    (never ``cv2.imread(path)``: a file name that is not UTF-8 crashed OpenCV with a segfault), and an
    image over OpenCV's pixel limit (CV_IO_MAX_IMAGE_PIXELS) is None, not an exception."""
    if not data:
        return None
    try:
        gray = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    except cv2.error:
        return None
    return gray if gray is not None and gray.size > 0 else None


def read_gray(path: str | Path) -> np.ndarray | None:
    """``decode_gray`` of a file's bytes; None when it cannot be read or decoded."""
    try:
        return decode_gray(Path(path).read_bytes())
    except OSError:
        return None


def classify_file(
    path: str | Path,
    spec: BoardSpec,
    settings: DetectorSettings | None = None,
    on_decoded: DecodedCallback | None = None,
) -> ImageOutcome:
    """Read, hash, decode and detect one image file (safe to call in a worker process).

    ``on_decoded(gray)`` is called with the decoded (H, W) uint8 image before detection, so a caller
    that needs the pixels too does not decode the file a second time.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        return ImageOutcome(
            path.name, str(path), UNREADABLE, f"cannot read the file: {exc.strerror}", None, ""
        )
    digest = hashlib.sha256(data).hexdigest()
    gray = decode_gray(data)
    if gray is None:
        return ImageOutcome(
            path.name, str(path), UNREADABLE, f"not a decodable image ({len(data)} bytes)", None, digest
        )
    if on_decoded is not None:
        on_decoded(gray)
    return classify_array(path.name, str(path), gray, digest, spec, settings)


def session_image_size(outcomes: Sequence[ImageOutcome]) -> tuple[int, int] | None:
    """Most common size among readable images; ties go to the size seen first."""
    sizes = [o.image_size for o in outcomes if o.image_size is not None]
    if not sizes:
        return None
    counts = Counter(sizes)
    best = max(counts.values())
    return next(s for s in sizes if counts[s] == best)


def finalize_session(
    outcomes: Sequence[ImageOutcome],
    image_size: tuple[int, int] | None = None,
    near_duplicate_frac: float = NEAR_DUPLICATE_FRAC,
) -> list[ImageOutcome]:
    """Apply the session-wide rules (size, near-duplicates) to per-file outcomes, in the given order."""
    size = image_size or session_image_size(outcomes)
    final: list[ImageOutcome] = []
    kept: list[ImageOutcome] = []
    for outcome in outcomes:
        if outcome.image_size is not None and size is not None and outcome.image_size != size:
            final.append(
                replace(
                    outcome,
                    status=WRONG_SIZE,
                    reason=(
                        f"image is {outcome.image_size[0]}x{outcome.image_size[1]} but the session's "
                        "images are "
                        f"{size[0]}x{size[1]}"
                    ),
                )
            )
            continue
        if outcome.status == ACCEPTED:
            twin = find_near_duplicate(outcome, kept, near_duplicate_frac)
            if twin is not None:
                other, moved = twin
                limit = near_duplicate_frac * float(np.hypot(*outcome.image_size))  # type: ignore[misc]
                final.append(
                    replace(
                        outcome,
                        status=NEAR_DUPLICATE,
                        reason=(
                            f"same view as {other.name}: corners moved {moved:.1f} px on average (limit "
                            f"{limit:.1f} px)"
                        ),
                    )
                )
                continue
            kept.append(outcome)
        final.append(outcome)
    return final


def mean_corner_motion_px(
    ids_a: np.ndarray, px_a: np.ndarray, ids_b: np.ndarray, px_b: np.ndarray
) -> float | None:
    """Mean displacement over the corner ids two detections share; None when they share fewer than 4."""
    if (
        ids_a.shape == ids_b.shape
        and len(ids_a) >= 4
        and np.array_equal(ids_a, ids_b)
        and bool(np.all(ids_a[1:] > ids_a[:-1]))
    ):
        # the same ids in ascending order (a whole board, the usual case): the intersection below would
        # pair row i with row i; this is that, bit for bit, without its sort (96 views: 4 560 pairs)
        return float(np.linalg.norm(px_a - px_b, axis=1).mean())
    common, ia, ib = np.intersect1d(ids_a, ids_b, assume_unique=True, return_indices=True)
    if common.size < 4:
        return None
    return float(np.linalg.norm(px_a[ia] - px_b[ib], axis=1).mean())


def find_near_duplicate(
    outcome: ImageOutcome, kept: Sequence[ImageOutcome], frac: float = NEAR_DUPLICATE_FRAC
) -> tuple[ImageOutcome, float] | None:
    """The closest earlier kept view within the near-duplicate limit, with its mean corner motion."""
    assert (
        outcome.corner_ids is not None and outcome.corners_px is not None and outcome.image_size is not None
    )
    limit = frac * float(np.hypot(*outcome.image_size))
    best: tuple[ImageOutcome, float] | None = None
    for other in kept:
        if other.corner_ids is None or other.corners_px is None:
            continue
        moved = mean_corner_motion_px(
            outcome.corner_ids, outcome.corners_px, other.corner_ids, other.corners_px
        )
        if moved is not None and moved < limit and (best is None or moved < best[1]):
            best = (other, moved)
    return best


def _classify_task(
    path: Path, spec: BoardSpec, settings: DetectorSettings | None, summarize: Summarize | None
) -> tuple[ImageOutcome, object]:
    """``classify_file`` plus ``summarize(gray)`` of the decoded image, in a worker (thread or process)."""
    summary: list[object] = []
    hook = None if summarize is None else (lambda gray: summary.append(summarize(gray)))
    outcome = classify_file(path, spec, settings, hook)
    return outcome, (summary[0] if summary else None)


def choose_executor(executor: str, workers: int, total: int) -> str:
    """ "thread" or "process" for a run of ``total`` files on ``workers`` workers (``executor`` "auto"
    decides).

    auto: processes from ``PROCESS_MIN_FILES`` files on, or whenever the pool is warm already (a
    station, a second capture in one process: no start-up to pay), threads otherwise. Threads share one GIL,
    and the Python side of each detection (grid checks, canonical order, sha256 of small files) then runs one
    at a time: 96 renders at 1280x960 on 2 cores took 1.30 s on 2 threads and 0.83 s on 2 processes. A pool of
    processes costs its start-up, ~0.3 s on 2 cores (20 renders: 0.22 s on 2 threads, 0.50 s on 2 fresh
    processes), which a warm pool (``worker_pool``) pays once per calibctl process.
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    if executor != "auto":
        return executor
    if workers > 1 and (total >= PROCESS_MIN_FILES or worker_pool.is_warm(workers)):
        return "process"
    return "thread"


def classify_files(
    paths: Sequence[str | Path],
    spec: BoardSpec,
    settings: DetectorSettings | None = None,
    workers: int | None = None,
    progress: ProgressCallback | None = None,
    executor: str = DEFAULT_EXECUTOR,
    summarize: Summarize | None = None,
    on_summary: SummaryCallback | None = None,
    known: KnownCallback | None = None,
) -> list[ImageOutcome]:
    """Per-file outcomes (no session rules) in the order of ``paths``, detected on ``workers`` workers.

    ``workers``: default the cores this process may run on (``worker_pool.available_cores``). The
    outcomes do not depend on it nor on ``executor`` ("auto", "thread" or "process", see
    ``choose_executor``): every worker detects with one OpenCV and one BLAS thread, so corners are
    bit-identical at every job count (tests/core/capture/test_parallel_detect.py).
    ``summarize(gray)`` (a module-level function, so a worker process can run it) is applied in the
    worker to each decoded (H, W) uint8 image, and ``on_summary(result)`` is called with it in the
    calling thread: a caller that needs something of the pixels too does not decode the file again.
    ``progress(done, total, outcome)`` is called in the calling thread for each file, as its task finishes (on
    processes a task is a few consecutive files, ``task_chunks``). On KeyboardInterrupt (or any exception) the
    tasks not yet started are cancelled and the exception propagates at once; nothing is returned. The process
    pool is kept warm for the next call (a task already running finishes its files there, unreported).
    ``known(path)``: a file's ``(outcome, summary)`` detected earlier by ``start_file`` with the same
    ``spec``, ``settings`` and ``summarize`` (a station watching its folder, ``core.capture.arrivals``), or
    None to detect it here; the known ones are reported first.
    """
    files = [Path(p) for p in paths]
    total = len(files)
    results: list[ImageOutcome | None] = [None] * total
    counted = 0

    def finished(i: int, outcome: ImageOutcome, summary: object, done: int) -> None:
        results[i] = outcome
        if on_summary is not None and summary is not None:
            on_summary(summary)
        if progress:
            progress(counted + done, total, outcome)

    todo = list(range(total))
    if known is not None:
        early = {i: known(files[i]) for i in todo}
        for i, found in early.items():
            if found is not None:
                counted += 1
                finished(i, *found, 0)
        todo = [i for i in todo if early[i] is None]
    _detect(files, todo, spec, settings, workers, executor, summarize, finished)
    return [r for r in results if r is not None]


def _detect(
    files: list[Path],
    todo: list[int],
    spec: BoardSpec,
    settings: DetectorSettings | None,
    workers: int | None,
    executor: str,
    summarize: Summarize | None,
    finished: Callable[[int, ImageOutcome, object, int], None],
) -> None:
    """``classify_files``' detection of the files numbered ``todo``."""
    if not todo:
        return
    workers = max(1, min(workers or worker_pool.available_cores(), len(todo)))
    kind = choose_executor(executor, workers, len(todo))
    with single_threaded_opencv():
        if workers == 1:
            for done, i in enumerate(todo, start=1):
                finished(i, *_classify_task(files[i], spec, settings, summarize), done)
        elif kind == "thread":
            pool = ThreadPoolExecutor(max_workers=workers)
            try:
                _collect(pool, files, [[i] for i in todo], spec, settings, summarize, finished)
            except BaseException:
                # Ctrl-C (or a failure): drop the queued files at once; only the images being detected
                # right now (one per worker) run to their end.
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown(wait=True)
        else:
            _collect(
                worker_pool.process_pool(workers),
                files,
                task_chunks(todo, workers),
                spec,
                settings,
                summarize,
                finished,
            )


def start_file(
    path: Path,
    spec: BoardSpec,
    workers: int,
    settings: DetectorSettings | None = None,
    summarize: Summarize | None = None,
) -> Future[tuple[ImageOutcome, object]]:
    """One file's ``classify_files`` task, started now: on the warm process pool when ``workers`` > 1, else
    run in this thread before returning (single-threaded OpenCV either way, so the outcome is the one
    ``classify_files`` gives the file at any job count)."""
    if workers > 1:
        for attempt in range(
            2
        ):  # a pool a dead worker broke is replaced once (its earlier files get detected again)
            pool = worker_pool.process_pool(workers)
            try:
                with worker_pool.shielded():
                    return worker_pool.submit(pool, _classify_task, path, spec, settings, summarize)
            except BrokenProcessPool as exc:
                worker_pool.discard_if_broken(pool)
                if attempt:
                    raise _worker_died([path]) from exc
    future: Future[tuple[ImageOutcome, object]] = Future()
    with single_threaded_opencv():
        future.set_result(_classify_task(path, spec, settings, summarize))
    return future


def task_chunks(todo: Sequence[int], workers: int) -> list[list[int]]:
    """``todo`` cut into consecutive runs, one process-pool task each, for ``workers`` workers.

    Why: each task costs the calling process ~0.6 ms of CPU (submit, the executor's manager and queue-feeder
    threads, the result's wake-up), 1/30 of a 1280x960 detection (~17 ms in a worker), taken from the cores
    the workers detect on. 96 renders on a warm pool of 2 (benchmarks/bench_pool_tasks.py, 2026-11-27, shared
    2-core host at load 3.3): the caller's CPU 0.056 s one file a task, 0.015 s in these tasks; the workers'
    1.58 and 1.54 s; wall 0.893 -> 0.812 s (benchmarks/results/station.md).
    How big: a run takes 1/(``CHUNK_SHARE`` x workers) of the files still left, at most ``CHUNK_MAX_FILES``
    (progress and Ctrl-C come between tasks), so the runs shrink to single files at the end and no worker sits
    idle while another finishes a long run (``multiprocessing.Pool.map``'s fixed n/(4 x workers) can leave
    one waiting for a whole run at the end). Every index once, in order: outcomes do not depend on it.
    """
    chunks: list[list[int]] = []
    start = 0
    while start < len(todo):
        size = max(1, min(CHUNK_MAX_FILES, (len(todo) - start) // (CHUNK_SHARE * max(1, workers))))
        chunks.append(list(todo[start : start + size]))
        start += size
    return chunks


def _classify_chunk(
    paths: Sequence[Path], spec: BoardSpec, settings: DetectorSettings | None, summarize: Summarize | None
) -> list[tuple[ImageOutcome, object]]:
    """``_classify_task`` of each of ``paths`` in turn: one process-pool task (``task_chunks``)."""
    return [_classify_task(path, spec, settings, summarize) for path in paths]


def _collect(
    pool: Executor,
    paths: list[Path],
    chunks: list[list[int]],
    spec: BoardSpec,
    settings: DetectorSettings | None,
    summarize: Summarize | None,
    finished: Callable[[int, ImageOutcome, object, int], None],
) -> None:
    """Detect each chunk of file numbers as one task of ``pool``; ``finished`` is called per file, in the
    chunk's order, as each task ends."""
    futures: dict[Future[list[tuple[ImageOutcome, object]]], list[int]] = {}
    try:
        # a process pool launches its workers inside submit: never interrupted half-way (worker_pool.shielded)
        with worker_pool.shielded() if isinstance(pool, ProcessPoolExecutor) else contextlib.nullcontext():
            for chunk in chunks:
                futures[_submit(pool, [paths[i] for i in chunk], spec, settings, summarize)] = chunk
        done = 0
        for future in as_completed(futures):
            for i, result in zip(futures[future], future.result(), strict=True):
                done += 1
                finished(i, *result, done)
    except BaseException as exc:
        for future in futures:  # queued files never start; the pool itself stays usable
            future.cancel()
        if isinstance(pool, ProcessPoolExecutor):
            worker_pool.discard_if_broken(pool)
        if isinstance(exc, BrokenProcessPool):
            raise _worker_died(
                [paths[i] for future, chunk in futures.items() if not _succeeded(future) for i in chunk]
            ) from exc
        raise


def _submit(
    pool: Executor,
    paths: list[Path],
    spec: BoardSpec,
    settings: DetectorSettings | None,
    summarize: Summarize | None,
) -> Future[list[tuple[ImageOutcome, object]]]:
    if isinstance(pool, ProcessPoolExecutor):  # the results through a file (worker_pool.submit says why)
        return worker_pool.submit(pool, _classify_chunk, paths, spec, settings, summarize)
    return pool.submit(_classify_chunk, paths, spec, settings, summarize)


def _succeeded(future: Future[list[tuple[ImageOutcome, object]]]) -> bool:
    return future.done() and not future.cancelled() and future.exception() is None


def _worker_died(unfinished: Sequence[Path]) -> WorkerDiedError:
    """A detection process that died (the kernel's out-of-memory killer, a crash in a decoder) breaks the
    whole pool: the files it had not finished are named, the pool is started afresh by the next capture."""
    names = [path.name for path in unfinished]
    return WorkerDiedError(
        f"a detection worker process died (killed, out of memory, or a crash decoding an image) with "
        f"{len(names)} image(s) not yet detected: {named_list(names, 3)}; nothing was stored",
        "run it again (the workers are started afresh); if it dies again, check the machine's free memory "
        "(dmesg names the out-of-memory killer) or leave the first image named above out",
    )


def classify_session(
    paths: Sequence[str | Path],
    spec: BoardSpec,
    settings: DetectorSettings | None = None,
    workers: int | None = None,
    progress: ProgressCallback | None = None,
    image_size: tuple[int, int] | None = None,
    executor: str = DEFAULT_EXECUTOR,
) -> list[ImageOutcome]:
    """Every image's final outcome: ``classify_files`` then ``finalize_session``, in the order of
    ``paths``."""
    return finalize_session(classify_files(paths, spec, settings, workers, progress, executor), image_size)
