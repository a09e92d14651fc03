"""The plain camera-IMU calibration (the "afternoon script"), and the estimator's initial values.

Steps: a board pose per frame by PnP through the held lens (``core.extrinsics.board_pose``); the
camera's rotation rate between consecutive frames; td by normalised cross-correlation of |w_camera|
against |w_gyro| (``core.diagnostics.timeoffset``, t_imu = t_cam + td_s); R_imu_cam by Kabsch on the
(mean-removed) rates w_imu = R_imu_cam w_cam + b_gyro; the translation, gravity and accelerometer bias
by linear least squares on twice-differentiated camera positions and rotations:

    R_w_imu a_meas = p''_w_cam + R''_w_cam t_cam_imu - g_w + R_w_imu b_accel

(w = the board frame). Each step sees only its own signal, so errors pass from step to step: this is
the floor the joint estimator (``core.imu.solve``) is judged against, and where it starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.diagnostics.timeoffset import OffsetConfig, estimate_time_offset
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.imu.samples import CameraFrames, ImuInputError, ImuSamples, check_rate_ratio

MIN_POSE_FRAMES = 10
STEP_FRAMES = 3  # positions differenced over +/-3 frames: PnP noise / (3 h)^2 instead of / h^2


@dataclass(frozen=True)
class BoardTrack:
    """The camera's trajectory from PnP. t_s: (F,) camera clock; T_cam_w: (F, 4, 4) board (w) into
    camera; frame: (F,) index into ``CameraFrames`` of each pose (frames without a pose dropped)."""

    t_s: np.ndarray
    T_cam_w: np.ndarray
    frame: np.ndarray

    @property
    def T_w_cam(self) -> np.ndarray:
        return np.linalg.inv(self.T_cam_w)


@dataclass(frozen=True)
class PlainResult:
    """T_imu_cam: (4, 4) p_imu = R p_cam + t. td_s: t_imu = t_cam + td_s. gyro_bias_rad_s (3,),
    accel_bias_m_s2 (3,), gravity_w_m_s2 (3,) in the board frame. rate_ncc: the correlation peak."""

    T_imu_cam: np.ndarray
    td_s: float
    gyro_bias_rad_s: np.ndarray
    accel_bias_m_s2: np.ndarray
    gravity_w_m_s2: np.ndarray
    rate_ncc: float


def board_track(frames: CameraFrames) -> BoardTrack:
    """PnP per frame; frames with under 4 corners or no pose are left out.

    Raises:
        ImuInputError: fewer than ``MIN_POSE_FRAMES`` frames give a board pose.
    """
    t, poses, kept = [], [], []
    for f, (obj, img) in enumerate(zip(frames.object_points, frames.image_points, strict=True)):
        if obj.shape[0] < 4:
            continue
        T, _ = estimate_board_pose(obj, img, frames.camera_matrix, frames.dist_coeffs)
        if T is None:
            continue
        t.append(frames.t_s[f])
        poses.append(T)
        kept.append(f)
    if len(t) < MIN_POSE_FRAMES:
        raise ImuInputError(
            f"camera: only {len(t)} frames give a board pose (at least {MIN_POSE_FRAMES} needed); "
            "check the board and the intrinsics, or record the board in view"
        )
    return BoardTrack(np.array(t), np.array(poses), np.array(kept))


def camera_rates(track: BoardTrack, max_gap_factor: float = 1.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean rotation rate of the camera over each pair of consecutive poses.

    Returns:
        t_mid_s (m,), interval_s (m,), w_cam_rad_s (m, 3) in the camera frame; pairs further apart
        than ``max_gap_factor`` median frame periods (a dropped frame) are left out.
    """
    R_w_c = track.T_w_cam[:, :3, :3]
    dt = np.diff(track.t_s)
    rel = np.einsum("nji,njk->nik", R_w_c[:-1], R_w_c[1:])  # R_c(k)_c(k+1)
    w = se3.rotvecs_from_rotations(rel) / dt[:, None]
    keep = dt <= max_gap_factor * np.median(dt)
    mid = 0.5 * (track.t_s[:-1] + track.t_s[1:])
    return mid[keep], dt[keep], w[keep]


def mean_gyro(imu: ImuSamples, t_mid_s: np.ndarray, interval_s: np.ndarray) -> np.ndarray:
    """(m, 3) the gyro's mean over [t_mid - interval/2, t_mid + interval/2] (trapezoid integral)."""
    t = imu.t_s
    cum = np.concatenate(
        [
            np.zeros((1, 3)),
            np.cumsum(0.5 * (imu.gyro_rad_s[1:] + imu.gyro_rad_s[:-1]) * np.diff(t)[:, None], axis=0),
        ]
    )
    lo, hi = t_mid_s - interval_s / 2, t_mid_s + interval_s / 2
    a = np.stack([np.interp(lo, t, cum[:, k]) for k in range(3)], axis=1)
    b = np.stack([np.interp(hi, t, cum[:, k]) for k in range(3)], axis=1)
    return (b - a) / interval_s[:, None]


def kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) rotation R minimising sum |a_i - R b_i|^2 for (m, 3) a, b."""
    U, _, Vt = np.linalg.svd(a.T @ b)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


class TdUnobservableError(ImuInputError):
    """The rate cross-correlation cannot pin td (constant rate, no motion, no correlation)."""


def rate_alignment(
    imu: ImuSamples, track: BoardTrack, max_lag_s: float = 0.2, td_s: float | None = None
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """td_s by rate cross-correlation (unless given: then held), then R_imu_cam and the gyro bias by
    Kabsch on the rates.

    Returns:
        (td_s, peak NCC, R_imu_cam (3, 3), gyro bias (3,) rad/s).

    Raises:
        ImuUnitError: the gyro swings ~57 times the camera's rate (deg/s).
        TdUnobservableError: the cross-correlation cannot pin td (it names why).
    """
    t_mid, interval, w_cam = camera_rates(track)
    overlap_s = min(imu.t_s[-1], t_mid[-1]) - max(imu.t_s[0], t_mid[0])
    if overlap_s < 4 * max_lag_s:
        raise ImuInputError(
            f"the camera ({t_mid[0]:.3f}..{t_mid[-1]:.3f} s) and IMU ({imu.t_s[0]:.3f}..{imu.t_s[-1]:.3f} s) "
            f"logs overlap for {max(overlap_s, 0.0):.3f} s, under {4 * max_lag_s:g} s: check that both are "
            "stamped on one clock (ns since the epoch) and come from the same recording"
        )
    gyro_norm = np.linalg.norm(imu.gyro_rad_s, axis=1)
    cam_norm = np.linalg.norm(w_cam, axis=1)
    check_rate_ratio(float(np.std(gyro_norm)), float(np.std(cam_norm)))
    if td_s is None:
        est = estimate_time_offset(
            imu.t_s, gyro_norm, t_mid, cam_norm, OffsetConfig(max_lag_s=max_lag_s, max_sigma_s=np.inf)
        )
        if est.td_s is None:
            raise TdUnobservableError(f"camera-IMU rate alignment: {est.refused}")
        td, ncc = float(est.td_s), float(est.peak_ncc or 0.0)
    else:
        td, ncc = td_s, float("nan")
    w_imu = mean_gyro(imu, t_mid + td, interval)
    inside = (t_mid + td - interval / 2 >= imu.t_s[0]) & (t_mid + td + interval / 2 <= imu.t_s[-1])
    a, b = w_imu[inside], w_cam[inside]
    R = kabsch(a - a.mean(axis=0), b - b.mean(axis=0))
    bias = a.mean(axis=0) - R @ b.mean(axis=0)
    return td, ncc, R, bias


def _even_triples(t_s: np.ndarray, step: int) -> np.ndarray:
    """Indices k with poses k-step, k, k+step evenly spaced (within 10 %) at step median periods."""
    period = np.median(np.diff(t_s))
    k = np.arange(step, t_s.size - step)
    before, after = t_s[k] - t_s[k - step], t_s[k + step] - t_s[k]
    even = (np.abs(before - step * period) < 0.1 * period) & (np.abs(after - step * period) < 0.1 * period)
    return k[even]


def plain_calibration(
    imu: ImuSamples,
    frames: CameraFrames,
    track: BoardTrack | None = None,
    step_frames: int = STEP_FRAMES,
    td_s: float | None = None,
) -> PlainResult:
    """The afternoon script (module docstring).

    Raises:
        ImuInputError, ImuUnitError: the recording cannot be aligned (the message says why).
    """
    track = track or board_track(frames)
    td, ncc, R_i_c, b_g = rate_alignment(imu, track, td_s=td_s)
    T_w_c = track.T_w_cam
    h = step_frames * np.median(np.diff(track.t_s))
    k = _even_triples(track.t_s, step_frames)
    t_k = track.t_s[k] + td
    k = k[(t_k - h >= imu.t_s[0]) & (t_k + h <= imu.t_s[-1])]
    if k.size < 10:
        raise ImuInputError("camera and IMU overlap for fewer than 10 evenly spaced frames")
    p = T_w_c[:, :3, 3]
    R = T_w_c[:, :3, :3]
    p_dd = (p[k + step_frames] - 2 * p[k] + p[k - step_frames]) / h**2
    R_dd = (R[k + step_frames] - 2 * R[k] + R[k - step_frames]) / h**2
    # The second difference is the acceleration averaged with a triangle of half-width h: average the
    # accelerometer, rotated into the board frame, the same way.
    R_w_i_samples, inside = _imu_orientations(imu, track, td, R_i_c)
    acc_w = np.einsum("nij,nj->ni", R_w_i_samples, imu.accel_m_s2)
    rows_a, rows_b = [], []
    t_imu = imu.t_s
    for kk, tc in zip(k, track.t_s[k] + td, strict=True):
        sel = (np.abs(t_imu - tc) < h) & inside
        if sel.sum() < 3:
            continue
        wts = 1.0 - np.abs(t_imu[sel] - tc) / h
        wts /= wts.sum()
        R_w_i = R[kk] @ R_i_c.T
        rows_a.append(np.hstack([R_dd[np.searchsorted(k, kk)], -np.eye(3), R_w_i]))
        rows_b.append(wts @ acc_w[sel] - p_dd[np.searchsorted(k, kk)])
    A = np.vstack(rows_a)
    b = np.concatenate(rows_b)
    x = np.linalg.lstsq(A[:, :6], b, rcond=None)[0]
    t_c_i, g_w, b_a = x[:3], x[3:6], np.zeros(3)
    return PlainResult(se3.transform(R_i_c, -R_i_c @ t_c_i), td, b_g, b_a, g_w, ncc)


def _imu_orientations(
    imu: ImuSamples, track: BoardTrack, td_s: float, R_imu_cam: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3, 3) R_w_imu at each IMU sample, interpolated between camera poses (rotation vector of the
    step, linearly), and (n,) bool: the sample lies between two poses."""
    t_pose = track.t_s + td_s
    R_w_c = track.T_w_cam[:, :3, :3]
    i = np.clip(np.searchsorted(t_pose, imu.t_s) - 1, 0, t_pose.size - 2)
    frac = (imu.t_s - t_pose[i]) / (t_pose[i + 1] - t_pose[i])
    inside = (imu.t_s >= t_pose[0]) & (imu.t_s <= t_pose[-1])
    step = se3.rotvecs_from_rotations(np.einsum("nji,njk->nik", R_w_c[:-1], R_w_c[1:]))
    R = R_w_c[i] @ se3.rotations_from_rotvecs(step[i] * np.clip(frac, 0, 1)[:, None])
    return R @ R_imu_cam.T, inside
