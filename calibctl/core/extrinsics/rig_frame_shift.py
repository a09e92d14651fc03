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
