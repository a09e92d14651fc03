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

Detection runs per file, in parallel (``classify_files``); the size and near-duplicate decisions need the
whole session and run afterwards, in file-name order (``finalize_session``), so results are
deterministic whatever order the workers finish in.
"""

from __future__ import annotations

import hashlib
import multiprocessing
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import FOUND_INCONSISTENT, Detection, DetectorSettings, detect_board

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
DEFAULT_WORKERS = 2
EXECUTORS = ("thread", "process")
DEFAULT_EXECUTOR = "thread"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")

ProgressCallback = Callable[[int, int, "ImageOutcome"], None]
DecodedCallback = Callable[[np.ndarray], None]


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
    return sorted((p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES),
                  key=lambda p: p.name)


def classify_array(name: str, path: str, gray: np.ndarray, sha256: str, spec: BoardSpec,
                   settings: DetectorSettings | None = None) -> ImageOutcome:
    """Detect and blur-check one decoded (H, W) uint8 image; the session decisions come later."""
    settings = settings or DetectorSettings()
    size = (int(gray.shape[1]), int(gray.shape[0]))
    if min(size) < MIN_IMAGE_SIDE_PX:  # no board fits; the detectors' arithmetic assumes some pixels
        return ImageOutcome(name, path, NO_BOARD, f"the image is only {size[0]}x{size[1]} px, too small to hold a "
                            "board", size, sha256)
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
        reason = (f"board edges are {width:.1f} px wide (limit {settings.blur_max_edge_px:.1f} px): "
                  f"out of focus or moving")
    return _with_detection(ImageOutcome(name, path, status, reason, size, sha256, elapsed_s=elapsed), detection)


def _with_detection(outcome: ImageOutcome, detection: Detection) -> ImageOutcome:
    return replace(outcome, corner_ids=detection.corner_ids, corners_px=detection.corners_px,
                   method=detection.method, edge_width_px=detection.edge_width_px)


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


def classify_file(path: str | Path, spec: BoardSpec, settings: DetectorSettings | None = None,
                  on_decoded: DecodedCallback | None = None) -> ImageOutcome:
    """Read, hash, decode and detect one image file (safe to call in a worker process).

    ``on_decoded(gray)`` is called with the decoded (H, W) uint8 image before detection, so a caller
    that needs the pixels too does not decode the file a second time.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        return ImageOutcome(path.name, str(path), UNREADABLE, f"cannot read the file: {exc.strerror}", None, "")
    digest = hashlib.sha256(data).hexdigest()
    gray = decode_gray(data)
    if gray is None:
        return ImageOutcome(path.name, str(path), UNREADABLE,
                            f"not a decodable image ({len(data)} bytes)", None, digest)
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


def finalize_session(outcomes: Sequence[ImageOutcome], image_size: tuple[int, int] | None = None,
                     near_duplicate_frac: float = NEAR_DUPLICATE_FRAC) -> list[ImageOutcome]:
    """Apply the session-wide rules (size, near-duplicates) to per-file outcomes, in the given order."""
    size = image_size or session_image_size(outcomes)
    final: list[ImageOutcome] = []
    kept: list[ImageOutcome] = []
    for outcome in outcomes:
        if outcome.image_size is not None and size is not None and outcome.image_size != size:
            final.append(replace(outcome, status=WRONG_SIZE, reason=(
                f"image is {outcome.image_size[0]}x{outcome.image_size[1]} but the session's images are "
                f"{size[0]}x{size[1]}")))
            continue
        if outcome.status == ACCEPTED:
            twin = find_near_duplicate(outcome, kept, near_duplicate_frac)
            if twin is not None:
                other, moved = twin
                limit = near_duplicate_frac * float(np.hypot(*outcome.image_size))  # type: ignore[misc]
                final.append(replace(outcome, status=NEAR_DUPLICATE, reason=(
                    f"same view as {other.name}: corners moved {moved:.1f} px on average (limit {limit:.1f} px)")))
                continue
            kept.append(outcome)
        final.append(outcome)
    return final


def mean_corner_motion_px(ids_a: np.ndarray, px_a: np.ndarray, ids_b: np.ndarray, px_b: np.ndarray) -> float | None:
    """Mean displacement over the corner ids two detections share; None when they share fewer than 4."""
    common, ia, ib = np.intersect1d(ids_a, ids_b, assume_unique=True, return_indices=True)
    if common.size < 4:
        return None
    return float(np.linalg.norm(px_a[ia] - px_b[ib], axis=1).mean())


def find_near_duplicate(outcome: ImageOutcome, kept: Sequence[ImageOutcome],
                        frac: float = NEAR_DUPLICATE_FRAC) -> tuple[ImageOutcome, float] | None:
    """The closest earlier kept view within the near-duplicate limit, with its mean corner motion."""
    assert outcome.corner_ids is not None and outcome.corners_px is not None and outcome.image_size is not None
    limit = frac * float(np.hypot(*outcome.image_size))
    best: tuple[ImageOutcome, float] | None = None
    for other in kept:
        if other.corner_ids is None or other.corners_px is None:
            continue
        moved = mean_corner_motion_px(outcome.corner_ids, outcome.corners_px, other.corner_ids, other.corners_px)
        if moved is not None and moved < limit and (best is None or moved < best[1]):
            best = (other, moved)
    return best


def _init_worker() -> None:
    cv2.setNumThreads(1)


def _mp_context() -> multiprocessing.context.BaseContext:
    """forkserver where available, else spawn; never plain fork.

    Forking a process whose OpenCV thread pool has run (any earlier cv2 call in this process) copies
    its locked mutexes and deadlocks the child. The fork server is a fresh process that only imports
    this module, so workers forked from it start quickly and safely; it lives for the process.
    Like every non-fork start method it needs the ``if __name__ == "__main__":`` guard in scripts.
    """
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload([__name__])
        return ctx
    return multiprocessing.get_context("spawn")


def classify_files(paths: Sequence[str | Path], spec: BoardSpec, settings: DetectorSettings | None = None,
                   workers: int = DEFAULT_WORKERS, progress: ProgressCallback | None = None,
                   executor: str = DEFAULT_EXECUTOR, on_decoded: DecodedCallback | None = None) -> list[ImageOutcome]:
    """Per-file outcomes (no session rules) in the order of ``paths``, detected on ``workers`` workers.

    ``executor`` is "thread" (default) or "process". OpenCV releases the GIL in decoding and
    detection, so threads scale across cores without a pool start-up. benchmarks/bench_detect.py,
    20 PNGs on 2 cores, 640x480 / 1280x960: 2 threads 95 / 201 ms, one worker 146 / 373 ms,
    2 processes 146-158 / 294-496 ms (the first process run also starts the fork server). OpenCV's
    own thread pool is set to one thread for the run (restored afterwards) so the workers do not
    oversubscribe the cores.
    ``on_decoded(gray)`` is called in the worker thread with each decoded image (it must be thread-safe;
    threads only: a worker process cannot call back into this one).
    ``progress(done, total, outcome)`` is called in the calling thread as each file finishes. On
    KeyboardInterrupt (or any exception) the files not yet started are cancelled and the exception
    propagates; nothing is returned.
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    if on_decoded is not None and executor == "process":
        raise ValueError("on_decoded needs the thread executor: a worker process cannot call back")
    paths = [Path(p) for p in paths]
    total = len(paths)
    results: list[ImageOutcome | None] = [None] * total
    workers = max(1, min(workers, total))
    threads_before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        if workers == 1:
            for i, path in enumerate(paths):
                results[i] = classify_file(path, spec, settings, on_decoded)
                if progress:
                    progress(i + 1, total, results[i])  # type: ignore[arg-type]
        else:
            pool: Executor = (ThreadPoolExecutor(max_workers=workers) if executor == "thread" else
                              ProcessPoolExecutor(max_workers=workers, mp_context=_mp_context(),
                                                  initializer=_init_worker))
            try:
                futures = {pool.submit(classify_file, path, spec, settings, on_decoded): i
                           for i, path in enumerate(paths)}
                for done, future in enumerate(as_completed(futures), start=1):
                    results[futures[future]] = future.result()
                    if progress:
                        progress(done, total, results[futures[future]])  # type: ignore[arg-type]
            except BaseException:
                # Ctrl-C (or a failure): drop the queued files at once; only the images being detected
                # right now (one per worker) run to their end.
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown(wait=True)
    finally:
        cv2.setNumThreads(threads_before)
    return [r for r in results if r is not None]


def classify_session(paths: Sequence[str | Path], spec: BoardSpec, settings: DetectorSettings | None = None,
                     workers: int = DEFAULT_WORKERS, progress: ProgressCallback | None = None,
                     image_size: tuple[int, int] | None = None, executor: str = DEFAULT_EXECUTOR) -> list[ImageOutcome]:
    """Every image's final outcome: ``classify_files`` then ``finalize_session``, in the order of ``paths``."""
    return finalize_session(classify_files(paths, spec, settings, workers, progress, executor), image_size)
