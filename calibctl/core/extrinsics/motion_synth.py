"""Seeded motion logs with a known X = T_a_b, for tests, benchmarks and ``calibctl synth-motions``,
and robot-arm poses for rendered board views.

Two shapes, matching the two inputs of ``calibctl handeye``:

- a pose log: sensor a follows a smooth trajectory, sampled as keyframes at ``rate_hz``; sensor b,
  rigidly attached, is sampled ``time_offset_s`` later (its clock runs late), and both poses get
  independent Gaussian noise. Excitation: "3d" (roll, pitch, yaw each +/- the amplitude), "planar"
  (yaw only, a ground robot) or "corridor" (a straight drive with +/- 1 deg of yaw corrections).
- independent relative motions: each motion of a turns by an angle drawn from [amplitude/2,
  amplitude] about a random axis (z only for "planar", none for "corridor") and translates by
  N(0, 0.3 m); B = X^-1 A X, and noise goes into A's motion only, independently per motion (the
  seed's conditioning setting: an error in the motion translation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics import se3

EXCITATIONS = ("3d", "planar", "corridor")
CORRIDOR_YAW_DEG = 1.0
MOTION_TRANSLATION_SIGMA_M = 0.3
# incommensurate frequencies (Hz) so roll, pitch and yaw never move in lock step
_FREQ_HZ = np.array([0.11, 0.17, 0.07])
_PHASE = np.array([0.3, 1.1, 2.0])


@dataclass(frozen=True)
class MotionLog:
    """Synthetic data with its truth. t_s: (n,) keyframe times of a; poses (n, 4, 4) or motions (n, 4, 4)."""

    t_s: np.ndarray
    T_first: np.ndarray  # poses T_wa_a, or motions T_a0_a1
    T_second: np.ndarray  # poses T_wb_b, or motions T_b0_b1
    T_a_b: np.ndarray
    shape: str  # "poses" or "motions"
    time_offset_s: float


def _check(excitation: str, n: int) -> None:
    if excitation not in EXCITATIONS:
        raise ValueError(f"unknown excitation {excitation!r}; expected one of {', '.join(EXCITATIONS)}")
    if n < 2:
        raise ValueError(f"need at least 2 samples, got {n}")


def trajectory_pose(t_s: float, excitation: str, amplitude_deg: float) -> np.ndarray:
    """T_wa_a at time t: a smooth loop (radius 2 m, 20 s per lap) with the chosen rotation excitation."""
    amp = np.radians(amplitude_deg)
    angles = amp * np.sin(2 * np.pi * _FREQ_HZ * t_s + _PHASE)
    if excitation == "planar":
        angles[:2] = 0.0
    elif excitation == "corridor":
        angles = np.array([0.0, 0.0, np.radians(CORRIDOR_YAW_DEG) * np.sin(2 * np.pi * _FREQ_HZ[2] * t_s)])
    if excitation == "corridor":
        position = np.array([1.5 * t_s, 0.0, 0.0])
    else:
        lap = 2 * np.pi * t_s / 20.0
        z = 0.0 if excitation == "planar" else 0.3 * np.sin(3 * lap)
        position = np.array([2.0 * np.cos(lap), 2.0 * np.sin(lap), z])
    R = (
        se3.rotation_from_rotvec([0, 0, angles[2]])
        @ se3.rotation_from_rotvec([0, angles[1], 0])
        @ se3.rotation_from_rotvec([angles[0], 0, 0])
    )
    return se3.transform(R, position)


def _noisy(T: np.ndarray, rng: np.random.Generator, rot_deg: float, trans_m: float) -> np.ndarray:
    R = se3.rotation_from_rotvec(rng.normal(0.0, np.radians(rot_deg), 3)) @ T[:3, :3]
    return se3.transform(R, T[:3, 3] + rng.normal(0.0, trans_m, 3))


def synthesize_pose_log(
    T_a_b: np.ndarray,
    n_poses: int,
    *,
    excitation: str = "3d",
    amplitude_deg: float = 45.0,
    rate_hz: float = 2.0,
    noise_rotation_deg: float = 0.0,
    noise_translation_m: float = 0.0,
    time_offset_s: float = 0.0,
    seed: int = 0,
) -> MotionLog:
    """Keyframe poses of a (T_wa_a) and of b (T_wb_b, wb = b's first pose, sampled ``time_offset_s`` late)."""
    _check(excitation, n_poses)
    rng = np.random.default_rng(seed)
    t = np.arange(n_poses) / rate_hz
    T_wa_b0 = trajectory_pose(time_offset_s, excitation, amplitude_deg) @ T_a_b
    T_wb_wa = se3.invert(T_wa_b0)
    first = [
        _noisy(trajectory_pose(ti, excitation, amplitude_deg), rng, noise_rotation_deg, noise_translation_m)
        for ti in t
    ]
    second = [
        _noisy(
            T_wb_wa @ trajectory_pose(ti + time_offset_s, excitation, amplitude_deg) @ T_a_b,
            rng,
            noise_rotation_deg,
            noise_translation_m,
        )
        for ti in t
    ]
    return MotionLog(
        t, np.array(first), np.array(second), np.asarray(T_a_b, np.float64), "poses", time_offset_s
    )


def synthesize_motions(
    T_a_b: np.ndarray,
    n_motions: int,
    *,
    excitation: str = "3d",
    amplitude_deg: float = 60.0,
    noise_rotation_deg: float = 0.0,
    noise_translation_m: float = 0.0,
    seed: int = 0,
) -> MotionLog:
    """Independent relative motions (A_i, B_i = X^-1 A_i X), noise on A's motion only."""
    _check(excitation, n_motions)
    rng = np.random.default_rng(seed)
    X = np.asarray(T_a_b, np.float64)
    X_inv = se3.invert(X)
    first, second = [], []
    for _ in range(n_motions):
        angle = np.radians(rng.uniform(amplitude_deg / 2.0, amplitude_deg))
        axis = {
            "3d": rng.standard_normal(3),
            "planar": np.array([0.0, 0.0, 1.0]),
            "corridor": np.array([0.0, 0.0, 1.0]),
        }[excitation]
        if excitation == "corridor":
            angle = np.radians(rng.uniform(-CORRIDOR_YAW_DEG, CORRIDOR_YAW_DEG))
        t = rng.normal(0.0, MOTION_TRANSLATION_SIGMA_M, 3)
        if excitation != "3d":
            t[2] = 0.0
        A = se3.transform(se3.rotation_from_rotvec(axis / np.linalg.norm(axis) * angle), t)
        second.append(X_inv @ A @ X)
        first.append(_noisy(A, rng, noise_rotation_deg, noise_translation_m))
    return MotionLog(
        np.arange(n_motions, dtype=np.float64), np.array(first), np.array(second), X, "motions", 0.0
    )


def robot_arm_poses(
    T_cam_board: list[np.ndarray],
    X: np.ndarray,
    *,
    eye_in_hand: bool = True,
    T_fixed: np.ndarray | None = None,
) -> np.ndarray:
    """(n, 4, 4) T_base_gripper that put the board at each wanted ``T_cam_board`` (from synth_scenes).

    Eye-in-hand: X = T_gripper_cam, the board fixed at ``T_fixed`` = T_base_board.
    Eye-to-hand: X = T_base_cam, the board fixed on the gripper at ``T_fixed`` = T_gripper_board.
    """
    if T_fixed is None:
        T_fixed = se3.transform(
            se3.rotation_from_rotvec(np.array([np.pi, 0.0, 0.0])), np.array([0.6, 0.0, 0.0])
        )
    if eye_in_hand:  # T_base_board = T_base_gripper X T_cam_board
        return np.array([T_fixed @ se3.invert(T) @ se3.invert(X) for T in T_cam_board])
    return np.array(
        [X @ T @ se3.invert(T_fixed) for T in T_cam_board]
    )  # T_base_cam T_cam_board = T_base_gripper T_gripper_board
