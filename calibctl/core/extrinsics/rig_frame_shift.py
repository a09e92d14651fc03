"""Whether one camera's frames are a whole frame off the others': the rig frames' relative poses say so.

Times pair the frames of a software-synchronised rig (core.extrinsics.rig_time_pairs), but they are only as
good as the recorder's file: when a camera's video holds one frame more or less at its start than its
timestamps say, every one of its frames is paired with the others' frame of the instant before or after,
and with a moving board no rigid rig fits them (caliscope-4cam: camera 1, 1.0-1.6 px left in the joint solve
where each camera alone fits at 0.13-0.19 px). Each frame's own relative pose shows it without a solve:
``T_a_b = T_a_board @ inv(T_b_board)`` of one rig frame is the rig's pose of b in a, the same for every
frame of a rigid rig that is paired right; paired with a neighbouring instant it scatters with the board's
motion. A camera is named when pairing its frames ``shift`` frames later (or earlier) cuts that scatter
to at most ``BETTER`` of what it is as paired, against every other camera it shares enough frames with.

The check names the shift, it never applies it: the user corrects the timestamps or declares the shift.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.extrinsics import se3

SHIFTS = (-1, 1)  # whole frames tried either way
MIN_FRAMES = 5  # rig frames a pair needs, as paired and as shifted, to be judged
BETTER = 0.6  # the shifted scatter must be at most this fraction of the scatter as paired


@dataclass(frozen=True)
class FrameShift:
    """``camera``'s video frame ``i + shift`` fits the other cameras' frames that times paired with its
    frame ``i``; ``scatter_mm`` / ``shifted_mm``: the median over its pairs of the relative poses' scatter
    (median distance of each frame's T_a_b translation from their median) as paired and shifted."""

    camera: str
    shift: int
    scatter_mm: float
    shifted_mm: float
    partners: tuple[str, ...]


def relative_scatter_mm(
    poses_a: Mapping[int, np.ndarray], poses_b: Mapping[int, np.ndarray], pairs: Sequence[tuple[int, int]]
) -> tuple[float, int]:
    """Scatter of T_a_b over the frame pairs (index in a, index in b) both cameras have a pose for (mm),
    and how many there were (nan with fewer than MIN_FRAMES)."""
    t_mm = [
        (poses_a[i] @ se3.invert(poses_b[j]))[:3, 3] * 1e3 for i, j in pairs if i in poses_a and j in poses_b
    ]
    if len(t_mm) < MIN_FRAMES:
        return float("nan"), len(t_mm)
    t = np.asarray(t_mm)
    return float(np.median(np.linalg.norm(t - np.median(t, axis=0), axis=1))), len(t_mm)


def frame_shifts(
    poses: Mapping[str, Mapping[int, np.ndarray]], groups: Sequence[Mapping[str, int]]
) -> list[FrameShift]:
    """The cameras (not the first: the reference) whose frames fit the others' one frame off.

    Args:
        poses: camera -> video frame index -> (4, 4) T_cam_board, metres (each frame's own PnP pose).
        groups: the rig frames, camera -> video frame index, as the times paired them.
    """
    cameras = list(poses)
    found = []
    for camera in cameras[1:]:
        for shift in SHIFTS:
            as_paired, shifted, partners = [], [], []
            for other in cameras:
                if other == camera:
                    continue
                pairs = [(g[camera], g[other]) for g in groups if camera in g and other in g]
                before, _ = relative_scatter_mm(poses[camera], poses[other], pairs)
                after, _ = relative_scatter_mm(
                    poses[camera], poses[other], [(i + shift, j) for i, j in pairs]
                )
                if np.isfinite(before) and np.isfinite(after):
                    as_paired.append(before)
                    shifted.append(after)
                    partners.append(other)
            if partners and all(a <= BETTER * b for a, b in zip(shifted, as_paired, strict=True)):
                found.append(
                    FrameShift(
                        camera, shift, float(np.median(as_paired)), float(np.median(shifted)), tuple(partners)
                    )
                )
    return found


# Exposure offsets the timestamps miss: a camera whose software timestamps lag (or lead) its exposures more
# than another's pairs frames that saw a moving board at different instants, by a fraction of a frame.
OFFSET_STEP_MS, OFFSET_MAX_MS = 5, 60  # the offsets tried: whole steps either way from 0
MIN_OFFSET_FRAMES = 8  # rig frames of the pair whose later camera has both neighbouring frames
OFFSET_GAIN = 0.7  # the best offset must leave at most this fraction of the pair's RMS as timestamped
MIN_OFFSET_S = 0.010  # offsets below this are within the scan's resolution and the board's acceleration
MIN_SHARED = 6  # corners a frame pair needs (as the rig's pairs)

Views = Mapping[int, tuple[np.ndarray, np.ndarray]]  # frame index -> (corner ids, (N, 2) px)


@dataclass(frozen=True)
class ExposureOffset:
    """Pair ``a``-``b``: the stereo RMS (intrinsics fixed) over ``frames`` rig frames as timestamped, and at
    ``offset_s``, the time b's corners are moved along their own image velocity that fits best."""

    a: str
    b: str
    frames: int
    rms_px: float
    offset_s: float
    offset_rms_px: float


def moved_corners(
    views: Views, times_s: Mapping[int, float], k: int, dt_s: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """Frame k's corners where they were ``dt_s`` later, along their image velocity between frames k - 1
    and k + 1 (the corners all three share); None without both neighbours and their times."""
    here, before, after = views.get(k), views.get(k - 1), views.get(k + 1)
    if here is None or before is None or after is None or k - 1 not in times_s or k + 1 not in times_s:
        return None
    span_s = times_s[k + 1] - times_s[k - 1]
    ids = np.intersect1d(np.intersect1d(here[0], before[0]), after[0])
    if len(ids) < MIN_SHARED or not span_s > 0:
        return None
    at = [v[1][np.searchsorted(v[0], ids)] for v in (here, before, after)]
    return ids, at[0] + dt_s * (at[2] - at[1]) / span_s


def exposure_offset(
    a: tuple[str, Views, np.ndarray, np.ndarray],
    b: tuple[str, Views, np.ndarray, np.ndarray],
    times_b_s: Mapping[int, float],
    pairs: Sequence[tuple[int, int]],
    object_points_m: np.ndarray,
    image_size: tuple[int, int],
) -> ExposureOffset | None:
    """The pair's best exposure offset (None with fewer than MIN_OFFSET_FRAMES): from 0, each way in
    OFFSET_STEP_MS steps while the RMS keeps falling (up to OFFSET_MAX_MS), so a pair whose frames fit best
    as timestamped costs three solves.

    Args:
        a, b: (name, views with ids sorted, K, dist) of two pinhole cameras.
        times_b_s: b's frame times, seconds; pairs: (frame of a, frame of b) of each rig frame.
        object_points_m: (N, 3) the board's corners by id.
    """
    usable = [(i, j) for i, j in pairs if i in a[1] and moved_corners(b[1], times_b_s, j, 0.0) is not None]
    if len(usable) < MIN_OFFSET_FRAMES:
        return None

    def rms(dt_s: float) -> float:
        objs, pts_a, pts_b = [], [], []
        for i, j in usable:
            ids_a, px_a = a[1][i]
            ids_b, px_b = moved_corners(b[1], times_b_s, j, dt_s)  # type: ignore[misc]
            common = np.intersect1d(ids_a, ids_b)
            if len(common) < MIN_SHARED:
                continue
            objs.append(object_points_m[common].astype(np.float32))
            pts_a.append(px_a[np.searchsorted(ids_a, common)].astype(np.float32))
            pts_b.append(px_b[np.searchsorted(ids_b, common)].astype(np.float32))
        if len(objs) < MIN_OFFSET_FRAMES:
            return float("nan")
        # copies: stereoCalibrate writes into the camera matrices it is given, even with them fixed
        K_a, d_a, K_b, d_b = (np.array(m, np.float64) for m in (a[2], a[3], b[2], b[3]))
        flags = cv2.CALIB_FIX_INTRINSIC
        try:
            found = cv2.stereoCalibrate(objs, pts_a, pts_b, K_a, d_a, K_b, d_b, image_size, flags=flags)
        except cv2.error:
            return float("nan")
        return float(found[0])

    scan = {0: rms(0.0)}
    if not np.isfinite(scan[0]):
        return None
    for step in (-OFFSET_STEP_MS, OFFSET_STEP_MS):
        ms = step
        while abs(ms) <= OFFSET_MAX_MS:
            scan[ms] = rms(ms / 1e3)
            if not scan[ms] < scan[ms - step]:  # rising (or no solve): the minimum lies behind
                break
            ms += step
    best = min((ms for ms in scan if np.isfinite(scan[ms])), key=lambda ms: scan[ms])
    return ExposureOffset(a[0], b[0], len(usable), scan[0], best / 1e3, scan[best])


def offset_matters(offset: ExposureOffset) -> bool:
    """The pair fits clearly better at an offset the timestamps do not record."""
    return abs(offset.offset_s) >= MIN_OFFSET_S and offset.offset_rms_px <= OFFSET_GAIN * offset.rms_px


# A declared exposure offset, applied: each frame's corners where they were at the frame's listed time,
# interpolated linearly in time between the frame and the neighbour exposed on the other side of that time.
MAX_GAP_FRAMES = 1.5  # a neighbour further than this many median frame intervals away is a gap, not a frame
MAX_MOTION_ROWS = 0.1  # corners that move more than this fraction of the image height between the two frames
DROP_NO_NEIGHBOUR = "no-neighbour"  # the neighbouring frame is missing or shows too few of the same corners
DROP_GAP = "neighbour-too-far-in-time"
DROP_MOTION = "motion-too-large"


def median_interval_s(times_s: Mapping[int, float]) -> float:
    """A camera's median interval between consecutive frames (seconds; nan with fewer than two)."""
    order = sorted(times_s)
    gaps = [times_s[k] - times_s[j] for j, k in zip(order, order[1:], strict=False) if k == j + 1]
    return float(np.median(gaps)) if gaps else float("nan")


def corners_at_listed_time(
    views: Views, times_s: Mapping[int, float], k: int, offset_s: float, interval_s: float, image_rows: int
) -> tuple[np.ndarray, np.ndarray] | str:
    """Frame k's corners at its listed time, for a camera whose frames were exposed ``offset_s`` after
    their listed times (``interval_s``: its median frame interval); or why the frame is dropped (DROP_*).

    Frame j was exposed at ``t_j + offset_s``; the listed time ``t_k`` lies between the exposures of k and
    j = k - 1 (a late camera) or k + 1 (an early one), so the corners are ``x_j + w (x_k - x_j)`` with
    ``w = (t_k - t_j - offset_s) / (t_k - t_j)``, over the corner ids both frames share.
    """
    if offset_s == 0.0:
        here = views.get(k)
        return here if here is not None else DROP_NO_NEIGHBOUR
    j = k - 1 if offset_s > 0 else k + 1
    here, there = views.get(k), views.get(j)
    if here is None or there is None or k not in times_s or j not in times_s:
        return DROP_NO_NEIGHBOUR
    span_s = times_s[k] - times_s[j]
    if not abs(span_s) <= MAX_GAP_FRAMES * interval_s or abs(offset_s) >= abs(span_s):
        return DROP_GAP
    ids = np.intersect1d(here[0], there[0])
    if len(ids) < MIN_SHARED:
        return DROP_NO_NEIGHBOUR
    x_k, x_j = here[1][np.searchsorted(here[0], ids)], there[1][np.searchsorted(there[0], ids)]
    if np.linalg.norm(x_k - x_j, axis=1).max() > MAX_MOTION_ROWS * image_rows:
        return DROP_MOTION
    w = (span_s - offset_s) / span_s
    return ids, x_j + w * (x_k - x_j)


# An exposure offset estimated from the data: the rig's residual over the offset, its minimum and the spread
# of that minimum over a bootstrap of the rig frames.
ESTIMATE_STEP_MS = 5.0
ESTIMATE_RESAMPLES = 200


def offset_minimum(
    offsets_ms: Sequence[float],
    squared_px2: Sequence[Mapping[tuple[str, int], float]],
    resamples: int = ESTIMATE_RESAMPLES,
    seed: int = 0,
) -> tuple[float, float] | None:
    """The offset where the mean squared residual is least (a parabola through the lowest scanned offset and
    its neighbours) and its sd over a bootstrap of the rig frames; None when the lowest offset is at either
    end of the scan, the parabola does not open upward (no minimum inside the scan), or the minimum leaves
    more than OFFSET_GAIN of the RMS at offset 0 (a residual that barely changes with the offset cannot
    place it: a board moving steadily hides an offset in the poses, and the minimum then lands anywhere).

    Args:
        offsets_ms: the scanned offsets, increasing, evenly spaced.
        squared_px2: per offset, (rig frame, camera) -> mean squared residual of that view (px^2); only the
            views every offset has are compared.
    """
    common = sorted(set.intersection(*(set(v) for v in squared_px2)))
    frames = sorted({f for f, _ in common})
    by_frame = {f: [k for k in common if k[0] == f] for f in frames}
    table = np.array([[v[k] for k in common] for v in squared_px2])  # (offsets, views)
    column = {k: i for i, k in enumerate(common)}

    def lowest(drawn: Sequence[str]) -> float | None:
        cols = [column[k] for f in drawn for k in by_frame[f]]
        ms2 = table[:, cols].mean(axis=1)
        i = int(np.argmin(ms2))
        if i in (0, len(offsets_ms) - 1):
            return None
        a, b, _ = np.polyfit(offsets_ms[i - 1 : i + 2], ms2[i - 1 : i + 2], 2)
        return float(-b / (2 * a)) if a > 0 else None

    best = lowest(frames) if frames else None
    ms2 = table.mean(axis=1) if frames else np.zeros(0)
    if best is None or not ms2.min() <= OFFSET_GAIN**2 * ms2[list(offsets_ms).index(0.0)]:
        return None
    rng = np.random.default_rng(seed)
    boot = [lowest([frames[i] for i in rng.integers(0, len(frames), len(frames))]) for _ in range(resamples)]
    found = [b for b in boot if b is not None]
    if len(found) < 0.9 * resamples:  # the minimum leaves the scan for many resamples: no stated sigma
        return None
    return best, float(np.std(found))
