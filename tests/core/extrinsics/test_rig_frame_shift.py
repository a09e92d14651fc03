"""A camera whose frames are paired one frame off the others' is named with the shift that fits; a rig paired
right, or a board that stands still (where no shift can tell), names none."""

from __future__ import annotations

import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.rig_frame_shift import frame_shifts

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
