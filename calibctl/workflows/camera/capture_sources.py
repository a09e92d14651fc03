"""Where a capture's pictures come from: a set of image files, a video file, or a live camera.

``resolve_source(text)`` decides what ``--source`` names, without opening anything:

* an existing folder -> ``folder`` (the image files directly in it);
* an existing file with an image suffix -> refused (a session is several images, not one);
* an existing file ending in .txt, .lst or .list -> ``list``: one image path per line, relative to
  the list file's folder (absolute paths as they are); blank lines and lines starting with # skipped;
* any other existing file -> ``video`` (decoded by cv2.VideoCapture);
* ``/dev/videoN`` or an integer that is not an existing path -> ``camera`` (cv2.VideoCapture);
* text with * ? or [ that is not an existing path -> ``glob`` (quoted, so the shell leaves it alone;
  ``**`` reaches into sub-folders), relative to the working directory;
* anything else -> refused as missing.

``select_images(spec)`` turns a folder, list or glob into the exact files of the session, named by
their path relative to the folder, the list file's folder (an absolute path in a list stays absolute)
or the glob's fixed leading folders (so a folder's images keep their plain file names). A glob or list
is an explicit choice of files, so files it names that are missing, or a glob matching nothing, stop
the capture (exit 2) - as do mixed image sizes among them (``mixed_sizes_error``), where a folder only
marks the odd ones "wrong_size".

Frame sources (``VideoFileSource``, ``CameraSource``) yield ``Frame`` objects in order. A video file
is read frame by frame, every frame, and its time is the video's own (frame index / fps), so a run on
a file is deterministic. A camera is read by a background thread that keeps only the newest frame:
detection then always works on a current frame and never falls behind the camera (frames that
arrive while a detection runs are dropped, not queued), and its time is wall-clock time.
"""

from __future__ import annotations

import contextlib
import glob
import math
import os
import re
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from queue import Full, Queue

import cv2
import numpy as np

from calibctl import bounded
from calibctl.core.capture import worker_pool
from calibctl.core.capture.image_outcomes import (
    DEFAULT_EXECUTOR,
    IMAGE_SUFFIXES,
    choose_executor,
    list_images,
)
from calibctl.errors import CalibctlError, FileSystemError, InputError, UsageError, named_list

FOLDER = "folder"
GLOB = "glob"
LIST = "list"
IMAGE_SETS = (FOLDER, GLOB, LIST)
LIST_SUFFIXES = (".txt", ".lst", ".list")
VIDEO = "video"
CAMERA = "camera"
DEFAULT_FPS = 30.0
CAMERA_READ_FAILURES_MAX = 30  # consecutive failed reads before a camera counts as gone
CAMERA_FRAME_WAIT_S = 5.0  # no new frame for this long: the camera stalled
_DEVICE = re.compile(r"^/dev/video[0-9]+$")
SOURCE_HINT = (
    "pass a folder of images, a quoted glob ('shots/left*.jpg'), a list file (.txt), a video file, "
    "or a camera (/dev/video0 or an index such as 0)"
)
NAMES_SHOWN = 10  # file names listed in an error before "and N more"
_GLOB_MAGIC = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class SourceSpec:
    """What ``--source`` names. ``target`` is a Path (folder, video) or a str/int for cv2.VideoCapture."""

    kind: str
    text: str
    target: Path | str | int

    @property
    def label(self) -> str:
        return str(self.target) if self.kind != CAMERA else f"camera {self.text}"

    @property
    def recorded(self) -> str:
        """What the session stores as its source: an absolute folder, list file or glob pattern."""
        if self.kind in (FOLDER, LIST):
            return str(Path(self.target).resolve())  # type: ignore[arg-type]
        if self.kind == GLOB:
            return str(Path(str(self.target)).absolute())
        return self.text


@dataclass(frozen=True)
class ImageSet:
    """The files of a folder, list or glob source. ``names[i]`` is ``paths[i]`` relative to ``base``;
    ``ignored``: files the folder or glob holds that are not images by their suffix."""

    paths: list[Path]
    names: list[str]
    base: Path
    ignored: list[str]

    def __post_init__(self) -> None:
        # names are recorded and printed: a byte that is not UTF-8 or a control character becomes \xNN
        object.__setattr__(self, "names", [bounded.printable(n) for n in self.names])
        object.__setattr__(self, "ignored", [bounded.printable(n) for n in self.ignored])


@dataclass(frozen=True)
class Frame:
    """One decoded frame. ``image``: (H, W) or (H, W, 3) uint8 as decoded (BGR); ``t_s``: seconds since
    the start of the stream (video time for files, wall time for cameras)."""

    index: int
    image: np.ndarray
    t_s: float

    @property
    def label(self) -> str:
        return f"frame-{self.index:06d}"


def resolve_source(text: str) -> SourceSpec:
    """Classify ``--source`` (see the module docstring); raises InputError/UsageError (exit 2)."""
    text = text.strip()
    if not text:
        raise UsageError("--source is empty", SOURCE_HINT)
    path = Path(text).expanduser()
    if _DEVICE.match(text):
        return SourceSpec(CAMERA, text, text)
    if path.is_dir():
        return SourceSpec(FOLDER, text, path)
    if path.is_file():
        if path.suffix.lower() in IMAGE_SUFFIXES:
            raise UsageError(
                f"--source {text} is a single image; a capture session is a folder of images",
                f"pass the folder that holds it ({path.parent}), or a quoted glob",
            )
        return SourceSpec(LIST if path.suffix.lower() in LIST_SUFFIXES else VIDEO, text, path)
    if path.exists():
        raise InputError(f"--source {text} is neither a folder, a regular file nor a camera", SOURCE_HINT)
    if _GLOB_MAGIC.search(text):
        return SourceSpec(GLOB, text, os.path.expanduser(text))
    if text.isdigit():
        return SourceSpec(CAMERA, text, int(text))
    raise InputError(f"--source {text} does not exist", SOURCE_HINT)


_OPENCV_LOG_LEVEL_ERROR = 2  # cv::utils::logging::LOG_LEVEL_ERROR


@contextlib.contextmanager
def quiet_opencv() -> Iterator[None]:
    """Silence OpenCV's own warnings while probing a device or file: we report the failure ourselves."""
    # OpenCV 5 has the log level in cv2.utils.logging, 4.x as cv2.getLogLevel/setLogLevel (same levels).
    api = getattr(cv2.utils, "logging", None) or cv2
    level = api.getLogLevel()
    api.setLogLevel(_OPENCV_LOG_LEVEL_ERROR)
    try:
        yield
    finally:
        api.setLogLevel(level)


def ignored_files(folder: Path) -> list[str]:
    """Visible regular files in ``folder`` that are not images by their suffix (reported, not read)."""
    return sorted(
        p.name
        for p in folder.iterdir()
        if p.is_file() and not p.name.startswith(".") and p.suffix.lower() not in IMAGE_SUFFIXES
    )


def _glob_base(pattern: str) -> Path:
    """The pattern's leading folders without wildcards ('shots/left*.jpg' -> shots)."""
    fixed = []
    for part in Path(pattern).parts[:-1]:
        if _GLOB_MAGIC.search(part):
            break
        fixed.append(part)
    return Path(*fixed) if fixed else Path(".")


def _image_set(paths: list[Path], base: Path, ignored: list[str]) -> ImageSet:
    return ImageSet(paths, [os.path.relpath(p, base) for p in paths], base, ignored)


def _folder_images(folder: Path) -> ImageSet:
    paths = list_images(folder)
    ignored = ignored_files(folder)
    if not paths:
        also = (
            f"; {len(ignored)} other file(s) ignored, not images by their suffix: "
            f"{named_list(ignored, NAMES_SHOWN)}"
            if ignored
            else ""
        )
        raise InputError(
            f"no images in {folder}{also}",
            f"put the session's images ({', '.join(IMAGE_SUFFIXES)}) in the folder",
        )
    return _image_set(paths, folder, ignored)


def _glob_images(pattern: str) -> ImageSet:
    matches = sorted(Path(m) for m in glob.glob(pattern, recursive=True))
    files = [p for p in matches if p.is_file()]
    paths = [p for p in files if p.suffix.lower() in IMAGE_SUFFIXES]
    base = _glob_base(pattern)
    ignored = [os.path.relpath(p, base) for p in files if p.suffix.lower() not in IMAGE_SUFFIXES]
    if not paths:
        also = (
            f" ({len(files)} file(s), none an image by its suffix: {named_list(ignored, NAMES_SHOWN)})"
            if files
            else ""
        )
        raise InputError(
            f"--source '{pattern}' matches no image file{also}; nothing was stored",
            "check the pattern (it is relative to the working directory) and quote it so the shell "
            "passes it on unexpanded",
        )
    return _image_set(paths, base, ignored)


def _listed_images(list_file: Path) -> ImageSet:
    try:
        lines = bounded.read_text(list_file, "read the list file").splitlines()
    except FileSystemError as exc:
        raise InputError(exc.message, "a list file is UTF-8 text") from exc
    base = list_file.parent
    paths: list[Path] = []
    names: list[str] = []  # each file as the list writes it: an absolute path stays absolute, not ../../..
    problems: list[str] = []
    for number, line in enumerate(lines, start=1):
        entry = line.strip()
        if not entry or entry.startswith("#"):
            continue
        given = Path(entry).expanduser()
        path = base / given
        if not path.is_file():
            problems.append(f"line {number}: {entry} ({'a folder' if path.is_dir() else 'missing'})")
        elif path.suffix.lower() not in IMAGE_SUFFIXES:
            problems.append(f"line {number}: {entry} (not an image by its suffix)")
        elif path not in paths:
            paths.append(path)
            names.append(str(path) if given.is_absolute() else os.path.relpath(path, base))
    if problems:
        raise InputError(
            f"the list file {list_file} names {len(problems)} file(s) that cannot be used; nothing was "
            f"stored: {named_list(problems, NAMES_SHOWN)}",
            f"paths in a list file are relative to its folder ({base}); fix or remove those lines",
        )
    if not paths:
        raise InputError(f"the list file {list_file} names no image", "put one image path per line")
    return ImageSet(paths, names, base, [])


def select_images(spec: SourceSpec) -> ImageSet:
    """The image files of a folder, glob or list source (InputError, exit 2, when there are none)."""
    if spec.kind == FOLDER:
        return _folder_images(Path(spec.target))  # type: ignore[arg-type]
    if spec.kind == GLOB:
        return _glob_images(str(spec.target))
    if spec.kind == LIST:
        return _listed_images(Path(spec.target))  # type: ignore[arg-type]
    raise ValueError(f"not an image-set source: {spec.kind}")


def start_detection_early(source: str, jobs: int) -> None:
    """Start the detection pool's fork server now when ``source`` will be detected on processes (a folder,
    glob or list of images that ``choose_executor`` sends to the pool at ``jobs``), before the caller imports
    its store and workflow: the server's imports run on another core meanwhile (a fresh 96-image capture
    waited ~0.2 s for them, benchmarks/results/station.md). A source that cannot be read is left to the
    capture to report."""
    if jobs <= 1:
        return
    try:
        spec = resolve_source(source)
        if spec.kind not in IMAGE_SETS:
            return
        count = len(select_images(spec).paths)
    except (CalibctlError, OSError):
        return
    if choose_executor(DEFAULT_EXECUTOR, jobs, count) == "process":
        worker_pool.start_server()


def mixed_sizes_error(spec: SourceSpec, sizes: dict[str, tuple[int, int]]) -> InputError | None:
    """For a glob or list: an error naming the files of each size when they are not all one size."""
    if spec.kind not in (GLOB, LIST) or len(set(sizes.values())) < 2:
        return None
    by_size: dict[tuple[int, int], list[str]] = {}
    for name, size in sizes.items():
        by_size.setdefault(size, []).append(name)
    groups = sorted(by_size.items(), key=lambda item: -len(item[1]))
    listing = "; ".join(f"{w}x{h}: {named_list(names, NAMES_SHOWN)}" for (w, h), names in groups)
    return InputError(
        f"--source {spec.text} mixes image sizes ({listing}); nothing was stored",
        "one session is one camera at one resolution: narrow the glob or list to one camera's images",
    )


class VideoFileSource:
    """Every frame of a video file, in order; time is the video's (index / fps)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        with quiet_opencv():
            self._capture = cv2.VideoCapture(str(path))
        if not self._capture.isOpened():
            self._capture.release()
            raise InputError(
                f"cannot decode the video {path}: OpenCV cannot open it",
                "is it a video? If so, convert it (e.g. ffmpeg -i IN -c:v mjpeg OUT.avi) and retry",
            )
        fps = float(self._capture.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = fps if math.isfinite(fps) and fps > 0 else DEFAULT_FPS
        self.frame_count = int(self._capture.get(cv2.CAP_PROP_FRAME_COUNT) or 0)

    def frames(self) -> Iterator[Frame]:
        index = 0
        while True:
            with quiet_opencv():
                ok, image = self._capture.read()
            if not ok or image is None:
                break
            yield Frame(index, image, index / self.fps)
            index += 1
        if index == 0:
            raise InputError(
                f"cannot decode the video {self.path}: not a single frame could be read",
                "the file is truncated or uses a codec this OpenCV lacks",
            )

    def close(self) -> None:
        self._capture.release()


class CameraSource:
    """The newest frame of a live camera, read by a background thread; time is wall-clock time."""

    def __init__(self, target: str | int, label: str) -> None:
        self.label = label
        if isinstance(target, str) and not Path(target).exists():
            present = sorted(str(p) for p in Path("/dev").glob("video*"))
            listing = ", ".join(present) if present else "none"
            raise InputError(
                f"cannot open {label}: {target} does not exist (video devices present: {listing})",
                "plug the camera in, or pass the device it appears as",
            )
        with quiet_opencv():
            self._capture = cv2.VideoCapture(target)
        if not self._capture.isOpened():
            self._capture.release()
            raise InputError(
                f"cannot open {label}: OpenCV could not open the device",
                "check the index or /dev/videoN, its permissions, and that no other program uses it",
            )
        self._cond = threading.Condition()
        self._latest: tuple[int, np.ndarray, float] | None = None
        self._ended = False
        self._stop = threading.Event()
        self._start = time.monotonic()
        self._thread = threading.Thread(target=self._read_loop, name="calibctl-camera", daemon=True)
        self._thread.start()

    def _read_loop(self) -> None:
        index = failures = 0
        while not self._stop.is_set():
            ok, image = self._capture.read()
            if not ok or image is None:
                failures += 1
                if failures >= CAMERA_READ_FAILURES_MAX:
                    break
                time.sleep(0.01)
                continue
            failures = 0
            with self._cond:
                self._latest = (index, image, time.monotonic() - self._start)
                self._cond.notify_all()
            index += 1
        with self._cond:
            self._ended = True
            self._cond.notify_all()

    def frames(self) -> Iterator[Frame]:
        last = -1

        def fresh() -> bool:
            return self._ended or (self._latest is not None and self._latest[0] > last)

        while True:
            with self._cond:
                if not self._cond.wait_for(fresh, timeout=CAMERA_FRAME_WAIT_S):
                    return  # stalled: end the stream, the caller finishes with what it kept
                if self._latest is None or self._latest[0] <= last:
                    return  # ended
                index, image, t_s = self._latest
            last = index
            yield Frame(index, image, t_s)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._capture.release()


@contextlib.contextmanager
def read_ahead(frames: Iterator[Frame], depth: int) -> Iterator[Iterator[Frame]]:
    """``frames`` read on a thread of their own, at most ``depth`` ahead of the consumer, in order; an
    exception of the reader (a decode error) is raised where the consumer would have met it. Leaving the block
    stops the reader (the frames it read ahead are dropped)."""
    queue: Queue[tuple[Frame | None, BaseException | None]] = Queue(maxsize=max(1, depth))
    stop = threading.Event()

    def offer(item: tuple[Frame | None, BaseException | None]) -> bool:
        while not stop.is_set():
            with contextlib.suppress(Full):
                queue.put(item, timeout=0.05)
                return True
        return False

    def read() -> None:
        try:
            for frame in frames:
                if not offer((frame, None)):
                    return
            offer((None, None))
        except BaseException as exc:  # noqa: BLE001 - whatever ends the reader is raised in the consumer
            offer((None, exc))

    def consume() -> Iterator[Frame]:
        while True:
            frame, error = queue.get()
            if error is not None:
                raise error
            if frame is None:
                return
            yield frame

    reader = threading.Thread(target=read, name="calibctl-read-ahead", daemon=True)
    reader.start()
    try:
        yield consume()
    finally:
        stop.set()
        reader.join()


def open_stream(spec: SourceSpec) -> VideoFileSource | CameraSource:
    """Open a video or camera source (InputError, exit 2, when it cannot be opened)."""
    if spec.kind == VIDEO:
        assert isinstance(spec.target, Path)
        return VideoFileSource(spec.target)
    if spec.kind == CAMERA:
        assert not isinstance(spec.target, Path)
        return CameraSource(spec.target, spec.label)
    raise ValueError(f"not a stream source: {spec.kind}")


def to_gray(image: np.ndarray) -> np.ndarray:
    """(H, W) uint8 from a decoded (H, W), (H, W, 3) BGR or (H, W, 4) BGRA frame."""
    if image.ndim == 2:
        return image
    code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
    return cv2.cvtColor(image, code)


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG bytes of a decoded frame (what goes into the image store for video/camera views)."""
    ok, buffer = cv2.imencode(".png", image)
    if not ok:
        raise InputError("cannot encode a frame as PNG")
    return buffer.tobytes()
