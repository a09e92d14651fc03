"""A rig captured as one video per camera (or one image folder per camera with a timestamps file): every
frame detected, the frames of one instant paired by time (core.extrinsics.rig_time_pairs), within a tolerance.

Where the times come from:
- ``--timestamps FILE``: the recorder's file (caliscope's ``timestamps.csv``:
  ``cam_id,frame_index,frame_time``). Its cam_ids are the rig's camera names (``--source 0=cam_0.mp4``);
  a cam_id that is not a camera, a camera it does not list, a frame listed twice, two frames of one camera
  at one time and frames past the end of the video are refused, naming the file. ``frame_index`` is the
  frame's index in the video (or the image's place in name order); a recorder that numbers the frames of its
  whole session (caliscope's frames 26..136 of a 111-frame file) is read from the file's first frame when its
  indices are one unbroken run exactly as long as the video (said in the report as the offset).
- no file: the container's own per-frame times (``CAP_PROP_POS_MSEC``). Each video's clock starts at its own
  first frame, so those times compare only when the recordings started together: videos of different lengths
  or frame rates are refused (give the recorder's timestamps).

Frames no other camera has within the tolerance are reported (``outside-time-tolerance``, with the time to
the nearest frame of another camera), never paired. Photo folders without a timestamps file keep the
last-number rule (core.extrinsics.rig_frames). A camera whose board is never found is refused naming its
video and what its frames show instead (core.capture.detect.charuco_variant_advice: "declare --inverted").
"""

from __future__ import annotations

import concurrent.futures
import hashlib
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from calibctl import bounded
from calibctl.artifacts.lint import Finding
from calibctl.core.board.board_spec import CHARUCO, BoardSpec
from calibctl.core.capture.detect import charuco_variant_advice, charuco_variant_counts
from calibctl.core.capture.image_circle import accumulate_max, half_size
from calibctl.core.capture.image_outcomes import ImageOutcome, classify_array, finalize_session, read_gray
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.extrinsics.rig_frame_shift import (
    corners_at_listed_time,
    exposure_offset,
    frame_shifts,
    median_interval_s,
    offset_matters,
)
from calibctl.core.extrinsics.rig_frames import FrameMatch, UnmatchedPhoto
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics
from calibctl.core.extrinsics.rig_time_pairs import (
    TimePairing,
    TimestampError,
    UnpairedFrame,
    pair_by_time,
    parse_timestamps,
)
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.errors import CalibctlError, InputError, UsageError
from calibctl.files import file_errors
from calibctl.workflows.camera import capture_sources

DEFAULT_TIME_TOLERANCE_MS = 5.0
OUTSIDE_TOLERANCE = "outside-time-tolerance"
NO_TIMESTAMP = "no-timestamp"
ADVICE_FRAMES = 12  # frames of a board-less camera the variant check looks at
FRAME_SHIFT = "rig-frame-shift"
EXPOSURE_OFFSET = "rig-exposure-offset"
CAMERA_HINT = "name the cameras as the timestamps file does, e.g. --source 0=cam_0.mp4 for cam_id 0"


@dataclass(frozen=True)
class CameraFrames:
    """One camera's frames: where they come from, their outcomes (in frame order), their times (seconds) and
    the per-pixel maximum at half size (for the image circle)."""

    name: str
    source: capture_sources.SourceSpec
    outcomes: tuple[ImageOutcome, ...]
    times_s: tuple[float | None, ...]
    max_gray: np.ndarray | None
    index_offset: int = 0


@dataclass(frozen=True)
class VideoRigCapture:
    """What the timed capture hands the rig flow: the frames as a FrameMatch (keys: rig frame numbers, paths:
    the frames' labels), each camera's outcomes, sources and maxima, and the time pairing itself."""

    match: FrameMatch
    cameras: Mapping[str, CameraFrames]
    pairing: TimePairing
    timestamps: Path | None
    frame_groups: tuple[Mapping[str, int], ...] = ()  # the rig frames: camera -> frame index in its video
    frame_shifts: Mapping[str, int] | None = None  # as declared (--frame-shift)
    frame_times: Mapping[str, tuple[float | None, ...]] | None = None  # per frame, as paired (seconds)
    exposure_offsets_s: Mapping[str, float] | None = None  # as declared (--exposure-offset)
    # the outcomes the rig solve reads: a declared offset's camera's corners at their frames' listed times
    rig_outcomes: Mapping[str, tuple[ImageOutcome, ...]] | None = None
    dropped: Mapping[str, Mapping[str, int]] | None = None  # camera -> why -> rig frames it left
    estimated_sd_s: Mapping[str, float] | None = None  # the offsets estimated from the data: their sd


def is_timed(sources: Mapping[str, Path], timestamps: Path | None) -> bool:
    """True when the rig is paired by time: a timestamps file is given, or a source is a video file."""
    if timestamps is not None:
        return True
    return any(_kind(source) == capture_sources.VIDEO for source in sources.values())


def _kind(source: Path) -> str | None:
    try:
        return capture_sources.resolve_source(str(source)).kind
    except CalibctlError:
        return None  # the photo path reports it


def frame_label(source: Path, index: int) -> str:
    """A frame's name in views and reports: ``cam_0.mp4#000026``."""
    return f"{source.name}#{index:06d}"


def _decoded_frames(
    name: str, spec: capture_sources.SourceSpec
) -> Iterator[tuple[str, np.ndarray, float | None]]:
    """(label, gray frame, container time in seconds or None) in order, for a video or an image set."""
    if spec.kind == capture_sources.VIDEO:
        path = Path(spec.target)  # type: ignore[arg-type]
        with capture_sources.quiet_opencv():
            capture = cv2.VideoCapture(str(path))
        try:
            if not capture.isOpened():
                raise InputError(
                    f"camera {name}: cannot decode the video {path}: OpenCV cannot open it",
                    "is it a video? If so, convert it (e.g. ffmpeg -i IN -c:v mjpeg OUT.avi) and retry",
                )
            count = 0
            while True:
                with capture_sources.quiet_opencv():
                    ok, image = capture.read()
                if not ok or image is None:
                    break
                t_ms = float(capture.get(cv2.CAP_PROP_POS_MSEC))
                yield (
                    frame_label(path, count),
                    capture_sources.to_gray(image),
                    t_ms / 1e3 if math.isfinite(t_ms) else None,
                )
                count += 1
            if count == 0:
                raise InputError(
                    f"camera {name}: cannot decode the video {path}: not a single frame could be read",
                    "the file is truncated or uses a codec this OpenCV lacks",
                )
        finally:
            capture.release()
        return
    images = capture_sources.select_images(spec)
    for path in images.paths:
        gray = read_gray(path)
        if gray is None:
            raise InputError(f"camera {name}: cannot decode the image {path}", "replace or remove the file")
        yield str(path), gray, None


def _frame_rate(spec: capture_sources.SourceSpec) -> float | None:
    if spec.kind != capture_sources.VIDEO:
        return None
    with capture_sources.quiet_opencv():
        capture = cv2.VideoCapture(str(spec.target))
    try:
        fps = float(capture.get(cv2.CAP_PROP_FPS) or 0.0)
    finally:
        capture.release()
    return fps if math.isfinite(fps) and fps > 0 else None


def detect_camera(name: str, source: Path, spec: BoardSpec, workers: int | None = None) -> CameraFrames:
    """Decode and detect every frame of one camera (threads: OpenCV releases the GIL), classified as a
    capture classifies photos (``finalize_session``: near duplicates, sizes)."""
    try:
        src = capture_sources.resolve_source(str(source))
    except CalibctlError as exc:
        raise type(exc)(f"camera {name}: {exc.message}", exc.hint) from exc
    if src.kind == capture_sources.CAMERA:
        raise InputError(f"--source {source} is a live camera; a rig is solved from recordings")
    outcomes: list[ImageOutcome] = []
    times: list[float | None] = []
    maximum: np.ndarray | None = None
    jobs = max(1, workers or 1)
    with (
        file_errors(f"read the {src.kind} of camera {name}", src.label),
        concurrent.futures.ThreadPoolExecutor(jobs) as pool,
    ):
        pending: list[concurrent.futures.Future[ImageOutcome]] = []
        for label, gray, t_s in _decoded_frames(name, src):
            digest = hashlib.sha256(gray.tobytes()).hexdigest()
            pending.append(pool.submit(classify_array, label, label, gray, digest, spec))
            times.append(t_s)
            maximum = accumulate_max(maximum, half_size(gray))
            if len(pending) >= 4 * jobs:
                outcomes.extend(f.result() for f in pending)
                pending = []
        outcomes.extend(f.result() for f in pending)
    return CameraFrames(name, src, tuple(finalize_session(outcomes)), tuple(times), maximum)


def read_timestamps(path: Path) -> dict[str, dict[int, float]]:
    """The recorder's timestamps file (InputError naming it when it cannot be used)."""
    try:
        text = bounded.read_text(path, "read the timestamps file")
    except CalibctlError as exc:
        raise InputError(exc.message, "give the recorder's timestamps file (a CSV)") from exc
    try:
        return parse_timestamps(text, str(path))
    except TimestampError as exc:
        raise InputError(str(exc), "fix the recorder's timestamps file, or leave it out to pair by the "
                         "videos' own times") from exc  # fmt: skip


def _file_times(
    name: str, label: str, n: int, listed: Mapping[int, float], timestamps: Path
) -> tuple[tuple[float | None, ...], int]:
    """Camera ``name``'s times of its ``n`` frames (``label``: its source) from the timestamps file, and the
    index offset (module docstring)."""
    indices = sorted(listed)
    offset = 0
    if indices[-1] >= n:
        unbroken = indices[-1] - indices[0] + 1 == len(indices)
        if not (unbroken and len(indices) == n):
            raise InputError(
                f"{timestamps} lists frame {indices[-1]} of camera {name}, but {label} "
                f"has {n} frames (0..{n - 1}): frames past the end",
                "give the timestamps file of this very recording (one row per frame of each video)",
            )
        offset = indices[0]
    return tuple(listed.get(i + offset) for i in range(n)), offset


def _listed_cameras(timestamps: Path, cameras: Sequence[str]) -> dict[str, dict[int, float]]:
    """The timestamps file, refused when it names a camera the rig lacks or lacks one of its cameras."""
    listed = read_timestamps(timestamps)
    unknown = sorted(set(listed) - set(cameras))
    if unknown:
        raise InputError(
            f"{timestamps} names camera {', '.join(unknown)}, which is not one of the rig's cameras "
            f"({', '.join(cameras)})",
            CAMERA_HINT,
        )
    absent = [name for name in cameras if name not in listed]
    if absent:
        raise InputError(f"{timestamps} lists no frame of camera {', '.join(absent)}", CAMERA_HINT)
    return listed


def pair_images_by_time(
    images: Mapping[str, Sequence[str]], timestamps: Path, tolerance_ms: float
) -> tuple[FrameMatch, TimePairing]:
    """A stored rig capture's images (camera -> image names in capture order: its frames 0..n-1) paired by
    the recorder's times, with the file rules of the videos (module docstring)."""
    if not (math.isfinite(tolerance_ms) and tolerance_ms > 0):
        raise UsageError(f"--time-tolerance-ms {tolerance_ms:g} must be a positive number of milliseconds")
    listed = _listed_cameras(timestamps, list(images))
    times = {
        name: _file_times(name, f"camera {name}'s source", len(paths), listed[name], timestamps)[0]
        for name, paths in images.items()
    }
    match, pairing, _ = _paired(images, times, tolerance_ms)
    return match, pairing


def shifted_times(times: Sequence[float | None], shift: int) -> tuple[float | None, ...]:
    """A camera's frame times when its video frame i was taken at the time listed for frame i - shift
    (a declared ``--frame-shift``); frames that then have no time get None."""
    n = len(times)
    return tuple(times[i - shift] if 0 <= i - shift < n else None for i in range(n))


def _container_times(cameras: Mapping[str, CameraFrames]) -> None:
    """Refuse container clocks that cannot be compared (module docstring)."""
    lengths = {name: len(c.outcomes) for name, c in cameras.items()}
    rates = {name: _frame_rate(c.source) for name, c in cameras.items()}
    hint = "give the recorder's timestamps file (--timestamps), which says when each frame was taken"
    if len(set(lengths.values())) > 1:
        listed = ", ".join(f"{cameras[n].source.label}: {k}" for n, k in lengths.items())
        raise InputError(f"the videos have different lengths ({listed} frames), so their own clocks did not "
                         "start together", hint)  # fmt: skip
    if len({round(r, 3) if r else r for r in rates.values()}) > 1:
        listed = ", ".join(f"{cameras[n].source.label}: {r or '?'} fps" for n, r in rates.items())
        raise InputError(f"the videos have different frame rates ({listed})", hint)
    for name, c in cameras.items():
        if any(t is None for t in c.times_s):
            raise InputError(f"{c.source.label} (camera {name}) carries no per-frame times", hint)


def refuse_blind_camera(camera: CameraFrames, spec: BoardSpec) -> None:
    """InputError when a ChArUco board is found on none of a camera's frames, saying what the frames show
    instead when another variant (polarity, layout, dictionary) reads them."""
    if spec.kind != CHARUCO or any(o.corner_ids is not None for o in camera.outcomes):
        return
    picks = np.linspace(0, len(camera.outcomes) - 1, min(ADVICE_FRAMES, len(camera.outcomes))).round()
    chosen = set(picks.astype(int).tolist())
    grays = [g for i, (_, g, _) in enumerate(_decoded_frames(camera.name, camera.source)) if i in chosen]
    advice = charuco_variant_advice(charuco_variant_counts(grays, spec), spec)
    seen = advice or f"no {spec.dictionary} marker on {len(grays)} sampled frame(s)"
    raise InputError(
        f"camera {camera.name}: the declared board is found on none of the {len(camera.outcomes)} frames of "
        f"{camera.source.label} ({seen})",
        "declare the board as printed (board add --inverted / --legacy / --dictionary), or check the video",
    )


def capture_timed(
    sources: Mapping[str, Path],
    spec: BoardSpec,
    timestamps: Path | None,
    tolerance_ms: float = DEFAULT_TIME_TOLERANCE_MS,
    workers: int | None = None,
    frame_shifts: Mapping[str, int] | None = None,
    exposure_offsets_s: Mapping[str, float] | None = None,
) -> VideoRigCapture:
    """Every camera's frames detected and paired by time (module docstring); ``frame_shifts``: camera ->
    N, its video frame i was taken at the time listed for its frame i - N; ``exposure_offsets_s``: camera ->
    seconds its frames were exposed after their listed times (``with_exposure_offsets``). Raises InputError
    / UsageError (exit 2) naming the file and the fix."""
    if not (math.isfinite(tolerance_ms) and tolerance_ms > 0):
        raise UsageError(f"--time-tolerance-ms {tolerance_ms:g} must be a positive number of milliseconds")
    for option, named in (("--frame-shift", frame_shifts), ("--exposure-offset", exposure_offsets_s)):
        unknown = sorted(set(named or {}) - set(sources))
        if unknown:
            raise UsageError(
                f"{option} names camera {', '.join(unknown)}, which is not one of the rig's cameras "
                f"({', '.join(sources)})"
            )
    listed = _listed_cameras(timestamps, list(sources)) if timestamps is not None else None
    cameras = {name: detect_camera(name, source, spec, workers) for name, source in sources.items()}
    if listed is None:
        _container_times(cameras)
        times = {name: c.times_s for name, c in cameras.items()}
    else:
        assert timestamps is not None
        timed = {
            name: _file_times(name, c.source.label, len(c.outcomes), listed[name], timestamps)
            for name, c in cameras.items()
        }
        times = {name: t for name, (t, _) in timed.items()}
        cameras = {name: replace(c, index_offset=timed[name][1]) for name, c in cameras.items()}
    for camera in cameras.values():
        refuse_blind_camera(camera, spec)
    shifts = {name: n for name, n in (frame_shifts or {}).items() if n}
    times = {name: shifted_times(ts, shifts.get(name, 0)) for name, ts in times.items()}
    paths = {name: [o.path for o in c.outcomes] for name, c in cameras.items()}
    match, pairing, in_video = _paired(paths, times, tolerance_ms)
    found = VideoRigCapture(match, cameras, pairing, timestamps, in_video, shifts or None, times)
    offsets = {name: s for name, s in (exposure_offsets_s or {}).items() if s}
    return with_exposure_offsets(found, offsets) if offsets else found


def with_exposure_offsets(capture: VideoRigCapture, offsets_s: Mapping[str, float]) -> VideoRigCapture:
    """The capture with each declared camera's corners moved to its frames' listed times: the camera's
    frames were exposed ``offsets_s[camera]`` after them (core.extrinsics.rig_frame_shift
    .corners_at_listed_time). A rig frame whose neighbour cannot carry the corners loses that camera
    (rig frames counted by reason); the camera's own outcomes, which calibrate its lens, are left as detected.
    UsageError when an offset is not shorter than the camera's frame interval (that is a frame shift)."""
    assert capture.frame_times is not None
    rig_outcomes, dropped = {}, {}
    for name, offset_s in offsets_s.items():
        outcomes = capture.cameras[name].outcomes
        times_s = {i: t for i, t in enumerate(capture.frame_times[name]) if t is not None}
        interval_s = median_interval_s(times_s)
        if not abs(offset_s) < interval_s:
            raise UsageError(
                f"--exposure-offset {name}={offset_s * 1e3:+g}: camera {name}'s frames are "
                f"{interval_s * 1e3:.1f} ms apart, so that is a whole frame or more",
                hint=f"declare whole frames with --frame-shift {name}=N and the rest with --exposure-offset",
            )
        views = {
            i: (o.corner_ids[order], o.corners_px[order])
            for i, o in enumerate(outcomes)
            if o.corner_ids is not None and o.corners_px is not None
            for order in [np.argsort(o.corner_ids)]
        }
        in_frames = {g[name] for g in capture.frame_groups if name in g}
        moved, why = list(outcomes), dict[str, int]()
        for i in sorted(views):  # every frame, so the image motion of the moved corners stays consistent
            rows = (outcomes[i].image_size or (0, 0))[1]
            at = corners_at_listed_time(views, times_s, i, offset_s, interval_s, rows)
            if isinstance(at, str):
                if i in in_frames:
                    why[at] = why.get(at, 0) + 1
                moved[i] = replace(outcomes[i], corner_ids=None, corners_px=None)
            else:
                moved[i] = replace(outcomes[i], corner_ids=at[0], corners_px=at[1])
        rig_outcomes[name], dropped[name] = tuple(moved), why
    return replace(capture, exposure_offsets_s=dict(offsets_s), rig_outcomes=rig_outcomes, dropped=dropped)


def rig_outcomes(capture: VideoRigCapture, name: str) -> tuple[ImageOutcome, ...]:
    """The outcomes of camera ``name`` the rig solve reads (with a declared exposure offset applied)."""
    return (capture.rig_outcomes or {}).get(name, capture.cameras[name].outcomes)


def _paired(
    paths: Mapping[str, Sequence[str]], times: Mapping[str, Sequence[float | None]], tolerance_ms: float
) -> tuple[FrameMatch, TimePairing, tuple[Mapping[str, int], ...]]:
    """The frames (camera -> their labels, in frame order) paired by their times; and the rig frames as
    camera -> frame index."""
    known = {name: [i for i, t in enumerate(ts) if t is not None] for name, ts in times.items()}
    timed = {name: [float(times[name][i] or 0.0) for i in idx] for name, idx in known.items()}
    try:
        pairing = pair_by_time(timed, tolerance_ms / 1e3)
    except ValueError as exc:
        raise UsageError(f"--time-tolerance-ms: {exc}", "give a smaller tolerance") from exc
    frames = tuple(
        (g.key, {name: paths[name][known[name][i]] for name, i in g.frames.items()}) for g in pairing.groups
    )
    unmatched = [
        UnmatchedPhoto(u.camera, paths[u.camera][known[u.camera][u.index]], _outside(u, tolerance_ms))
        for u in pairing.unpaired
    ]
    unmatched += [
        UnmatchedPhoto(name, paths[name][i], NO_TIMESTAMP)
        for name, ts in times.items()
        for i, t in enumerate(ts)
        if t is None
    ]
    in_frames = tuple({name: known[name][i] for name, i in g.frames.items()} for g in pairing.groups)
    return FrameMatch(frames, tuple(unmatched)), pairing, in_frames


def _outside(frame: UnpairedFrame, tolerance_ms: float) -> str:
    """Why a frame is in no rig frame, in words."""
    nearest = f"the nearest frame of another camera is {frame.nearest_s * 1e3:.1f} ms away"
    if frame.stretch_s is not None and frame.nearest_s * 1e3 <= tolerance_ms:
        return (
            f"{OUTSIDE_TOLERANCE}: {nearest}, in a rig frame this one would spread over "
            f"{frame.stretch_s * 1e3:.1f} ms (tolerance {tolerance_ms:g} ms)"
        )
    return f"{OUTSIDE_TOLERANCE}: {nearest} (tolerance {tolerance_ms:g} ms)"


def timing_json(capture: VideoRigCapture) -> dict[str, object]:
    """The pairing in plain JSON types: tolerance, frames paired, the spread of their times, offsets."""
    spreads = np.array([g.spread_s for g in capture.pairing.groups]) * 1e3
    return {
        "times": str(capture.timestamps) if capture.timestamps is not None else "video container",
        "tolerance_ms": capture.pairing.tolerance_s * 1e3,
        "rig_frames": len(capture.pairing.groups),
        "outside_tolerance": len(capture.pairing.unpaired),
        "spread_ms": {
            "median": float(np.median(spreads)) if spreads.size else None,
            "max": float(spreads.max()) if spreads.size else None,
        },
        "frames": {name: len(c.outcomes) for name, c in capture.cameras.items()},
        "index_offset": {name: c.index_offset for name, c in capture.cameras.items() if c.index_offset},
        "frame_shift": dict(capture.frame_shifts or {}),
        "exposure_offset_ms": {name: s * 1e3 for name, s in (capture.exposure_offsets_s or {}).items()},
        "exposure_dropped": {name: dict(why) for name, why in (capture.dropped or {}).items()},
        "exposure_offset_sd_ms": {name: s * 1e3 for name, s in (capture.estimated_sd_s or {}).items()},
    }


def frame_shift_findings(
    capture: VideoRigCapture, members: Sequence[MemberIntrinsics], spec: BoardSpec
) -> list[Finding]:
    """``rig-frame-shift`` (error) for each camera whose frames fit the others' a whole frame off the times'
    pairing (core.extrinsics.rig_frame_shift): every frame with a board posed through its member's lens."""
    points = spec.object_points()
    poses: dict[str, dict[int, np.ndarray]] = {}
    for member in members:
        frames = capture.cameras[member.name].outcomes
        model = "fisheye" if member.lens == "fisheye" else DEFAULT_MODEL
        poses[member.name] = {}
        for i, o in enumerate(frames):
            if o.corner_ids is None or o.corners_px is None:
                continue
            T_cam_board, _ = estimate_board_pose(
                points[o.corner_ids], o.corners_px, member.camera_matrix, member.dist_coeffs, model
            )
            if T_cam_board is not None:
                poses[member.name][i] = T_cam_board
    out = []
    for s in frame_shifts(poses, capture.frame_groups):
        declared = (capture.frame_shifts or {}).get(s.camera, 0)
        side = "later" if s.shift > 0 else "earlier"
        where = capture.timestamps if capture.timestamps is not None else "the videos' own times"
        out.append(
            Finding(
                rule=FRAME_SHIFT,
                severity="error",
                message=(
                    f"camera {s.camera}'s frames fit the other cameras' {abs(s.shift)} frame {side} than "
                    f"{where} pairs them: the rig frames' own relative poses scatter by "
                    f"{s.scatter_mm:.1f} mm as paired and by {s.shifted_mm:.1f} mm shifted (against "
                    f"{', '.join(s.partners)}), "
                    "so no rigid rig fits them as paired"
                ),
                fix=(
                    f"correct camera {s.camera}'s frame numbers in the timestamps, or declare the shift: "
                    f"--frame-shift {s.camera}={declared + s.shift:+d}"
                ),
            )
        )
    return out


def exposure_offset_findings(
    capture: VideoRigCapture, members: Sequence[MemberIntrinsics], spec: BoardSpec
) -> list[Finding]:
    """``rig-exposure-offset`` (error) for each pair of pinhole members whose frames fit clearly better with
    one camera's corners moved a fraction of a frame along their image motion
    (core.extrinsics.rig_frame_shift.exposure_offset): exposures further apart than the times say, while
    the board moved."""
    if capture.frame_times is None:
        return []
    views: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = {}
    for member in members:
        views[member.name] = {}
        for i, o in enumerate(rig_outcomes(capture, member.name)):
            if o.corner_ids is not None and o.corners_px is not None:
                order = np.argsort(o.corner_ids)
                views[member.name][i] = (o.corner_ids[order], o.corners_px[order])
    pinhole = [m for m in members if m.lens != "fisheye"]
    declared = capture.exposure_offsets_s or {}
    out = []
    for n, a in enumerate(pinhole):
        for b in pinhole[n + 1 :]:
            pairs = [(g[a.name], g[b.name]) for g in capture.frame_groups if a.name in g and b.name in g]
            times_b = {i: t for i, t in enumerate(capture.frame_times[b.name]) if t is not None}
            found = exposure_offset(
                (a.name, views[a.name], a.camera_matrix, a.dist_coeffs),
                (b.name, views[b.name], b.camera_matrix, b.dist_coeffs),
                times_b,
                pairs,
                spec.object_points(),
                a.image_size,
            )
            if found is None or not offset_matters(found):
                continue
            ms = abs(found.offset_s) * 1e3
            first, then = (a.name, b.name) if found.offset_s < 0 else (b.name, a.name)
            late_ms = (declared.get(b.name, 0.0) - found.offset_s) * 1e3  # b's exposures after its times
            out.append(
                Finding(
                    rule=EXPOSURE_OFFSET,
                    severity="error",
                    message=(
                        f"pair {a.name}-{b.name}: camera {first} exposed about {ms:.0f} ms before camera "
                        f"{then} at the same timestamp while the board moved (stereo RMS "
                        f"{found.rms_px:.2f} px as timestamped, {found.offset_rms_px:.2f} px with camera "
                        f"{b.name}'s corners moved {found.offset_s * 1e3:+.0f} ms along their image motion; "
                        f"{found.frames} rig frames): "
                        "a latency the timestamps do not record"
                    ),
                    fix=(
                        f"declare it (camera {b.name}'s frames exposed that long after their listed times): "
                        f"--exposure-offset {b.name}={late_ms:+.0f}"
                        "; or hold the board still at each pose (or trigger the cameras together)"
                    ),
                )
            )
    return out
