"""A camera whose frames are paired one frame off the others' is named with the shift that fits; a rig paired
right, or a board that stands still (where no shift can tell), names none. A declared exposure offset moves a
frame's corners to its listed time between it and the neighbour on the other side of that time, and drops the
frame when that neighbour is missing, a gap away or too far in the image."""

from __future__ import annotations

import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.rig_frame_shift import (
    DROP_GAP,
    DROP_MOTION,
    DROP_NO_NEIGHBOUR,
    corners_at_listed_time,
    frame_shifts,
    median_interval_s,
)

N_FRAMES = 20


def _rig_poses(moving: bool, noise_m: float = 0.001, seed: int = 3):
    """Three cameras 0.3 m apart; per frame the board's pose in each camera (T_cam_board), the board
    sweeping along a wavy path (or standing still), and PnP-like noise on each pose's translation."""
    rng = np.random.default_rng(seed)
    T_root_cam = [np.eye(4) for _ in range(3)]
    for c, x in enumerate((0.0, 0.3, -0.3)):
        T_root_cam[c] = se3.transform(se3.rotation_from_rotvec([0.0, -x, 0.0]), np.array([x, 0.0, 0.0]))
    poses: dict[str, dict[int, np.ndarray]] = {str(c): {} for c in range(3)}
    for frame in range(N_FRAMES):
        k = frame if moving else 0
        tilt = se3.rotation_from_rotvec([0.3 * np.sin(0.4 * k), 0.2 * np.cos(0.3 * k), 0.0])
        at = np.array([0.02 * k, 0.05 * np.sin(0.5 * k), 0.9])
        T_root_board = se3.transform(tilt, at)
        for c in range(3):
            T = se3.invert(T_root_cam[c]) @ T_root_board
            T[:3, 3] += rng.normal(0.0, noise_m, 3)
            poses[str(c)][frame] = T
    return poses


def test_a_camera_paired_one_frame_off_is_named_with_the_shift_that_fits():
    poses = _rig_poses(moving=True)
    groups = [{"0": k, "1": k, "2": k + 1} for k in range(N_FRAMES - 1)]  # camera 2 paired one frame late
    (found,) = frame_shifts(poses, groups)
    assert (found.camera, found.shift, found.partners) == ("2", -1, ("0", "1"))
    assert found.shifted_mm < found.scatter_mm


def test_a_rig_paired_right_names_no_camera():
    poses = _rig_poses(moving=True)
    assert frame_shifts(poses, [{"0": k, "1": k, "2": k} for k in range(N_FRAMES)]) == []


def test_a_still_board_names_no_camera_even_paired_off():
    poses = _rig_poses(moving=False)
    assert frame_shifts(poses, [{"0": k, "1": k, "2": k + 1} for k in range(N_FRAMES - 1)]) == []


def _moving_corners(speed_px_s: float, times_s: dict[int, float]):
    """Eight corners moving at a steady image velocity: frame k shows them at its exposure time, 30 ms after
    its listed time."""
    ids = np.arange(8)
    start = np.column_stack([100.0 + 10 * ids, 200.0 + 5 * ids])
    direction = np.array([0.6, 0.8])
    views = {k: (ids, start + speed_px_s * (t + 0.030) * direction) for k, t in times_s.items()}
    return ids, start, direction, views


def test_a_late_cameras_corners_move_back_to_their_listed_time():
    times_s = {k: 0.2 * k for k in range(5)}
    ids, start, direction, views = _moving_corners(100.0, times_s)
    interval_s = median_interval_s(times_s)
    got = corners_at_listed_time(views, times_s, 2, 0.030, interval_s, 720)
    assert not isinstance(got, str)
    np.testing.assert_array_equal(got[0], ids)
    np.testing.assert_allclose(got[1], start + 100.0 * 0.4 * direction, atol=1e-9)
    # an early camera interpolates towards its next frame instead; the last frame has none
    early = corners_at_listed_time(views, times_s, 2, -0.030, interval_s, 720)
    assert not isinstance(early, str)
    np.testing.assert_allclose(early[1], start + 100.0 * 0.46 * direction, atol=1e-9)
    assert corners_at_listed_time(views, times_s, 4, -0.030, interval_s, 720) == DROP_NO_NEIGHBOUR
    assert corners_at_listed_time(views, times_s, 0, 0.030, interval_s, 720) == DROP_NO_NEIGHBOUR


def test_a_frame_is_dropped_across_a_gap_or_a_large_motion():
    times_s = {0: 0.0, 1: 0.2, 2: 0.4, 3: 0.9, 4: 1.1}  # frame 3 follows a 0.5 s gap
    _, _, _, views = _moving_corners(100.0, times_s)
    interval_s = median_interval_s(times_s)
    assert corners_at_listed_time(views, times_s, 3, 0.030, interval_s, 720) == DROP_GAP
    _, _, _, fast = _moving_corners(400.0, times_s)  # 80 px between frames, more than 0.1 of 720 rows
    assert corners_at_listed_time(fast, times_s, 1, 0.030, interval_s, 720) == DROP_MOTION
    assert not isinstance(corners_at_listed_time(fast, times_s, 1, 0.030, interval_s, 1080), str)
