"""The continuous-time model: the IMU pose as a cubic B-spline, and what the camera and IMU see from it.

Frames: w = the board (target) frame; imu = the IMU body; cam = the camera. The IMU pose on the IMU
clock is R_w_imu(t) = R_ref Exp(phi(t)), p_w_imu(t) = p(t), with phi and p one uniform cubic B-spline
over 6-vectors [phi (3, rad), p (3, m)] (``core.imu.spline``); R_ref is a fixed rotation (the
initial middle pose) that keeps |phi| well below pi. Then

    gyro  = Jr(phi) phi'  + b_g                                (rad/s, IMU frame)
    accel = Exp(-phi) R_ref^T (p'' - g_w) + b_a                  (m/s^2, IMU frame; g_w points down)
    T_cam_w(t) = T_imu_cam^-1 T_w_imu(t)^-1                      (board into camera)

and a corner seen in a frame stamped t_cam, on image row v, was seen at t = t_cam + td_s (+ line
delay * (v - c_y) with a rolling shutter). All functions are vectorised over samples.
"""

from __future__ import annotations

import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.intrinsics.lens_checks import distort_normalised


def exp_so3(phi: np.ndarray) -> np.ndarray:
    """(m, 3) -> (m, 3, 3)."""
    return se3.rotations_from_rotvecs(phi)


def right_jacobian(phi: np.ndarray) -> np.ndarray:
    """(m, 3) -> (m, 3, 3) Jr(phi) = I - (1 - cos a)/a^2 K + (a - sin a)/a^3 K^2, K = skew(phi)."""
    a = np.linalg.norm(phi, axis=1)
    small = a < 1e-6
    a_safe = np.where(small, 1.0, a)
    c1 = np.where(small, 0.5 - a**2 / 24, (1 - np.cos(a)) / a_safe**2)
    c2 = np.where(small, 1.0 / 6 - a**2 / 120, (a - np.sin(a)) / a_safe**3)
    K = np.zeros((phi.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -phi[:, 2], phi[:, 1], -phi[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = phi[:, 2], -phi[:, 1], phi[:, 0]
    return np.eye(3) - c1[:, None, None] * K + c2[:, None, None] * (K @ K)


def spline_value(ctrl_local: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(m, 4, d) control points, (m, 4) basis weights -> (m, d)."""
    return np.einsum("mj,mjd->md", weights, ctrl_local)


def imu_pose(ctrl_local: np.ndarray, w0: np.ndarray, R_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R_w_imu (m, 3, 3), p_w_imu (m, 3)."""
    x = spline_value(ctrl_local, w0)
    return R_ref @ exp_so3(x[:, :3]), x[:, 3:]


def camera_pose(
    ctrl_local: np.ndarray, w0: np.ndarray, R_ref: np.ndarray, R_imu_cam: np.ndarray, t_imu_cam: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """T_cam_w as R (m, 3, 3), t (m, 3): R = R_ic^T R_w_i^T, t = R_ic^T (-R_w_i^T p - t_ic)."""
    R_w_i, p = imu_pose(ctrl_local, w0, R_ref)
    R_i_w = np.transpose(R_w_i, (0, 2, 1))
    t_i_w = -np.einsum("mij,mj->mi", R_i_w, p)
    return R_imu_cam.T @ R_i_w, (t_i_w - t_imu_cam) @ R_imu_cam


def imu_predict(
    ctrl_local: np.ndarray,
    w0: np.ndarray,
    w1: np.ndarray,
    w2: np.ndarray,
    R_ref: np.ndarray,
    gravity_w: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Bias-free gyro (m, 3) rad/s and accelerometer (m, 3) m/s^2 predictions."""
    phi = spline_value(ctrl_local[:, :, :3], w0)
    phi_dot = spline_value(ctrl_local[:, :, :3], w1)
    p_dd = spline_value(ctrl_local[:, :, 3:], w2)
    gyro = np.einsum("mij,mj->mi", right_jacobian(phi), phi_dot)
    R_i_w = np.transpose(R_ref @ exp_so3(phi), (0, 2, 1))
    accel = np.einsum("mij,mj->mi", R_i_w, p_dd - gravity_w)
    return gyro, accel


def project(points_cam: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray) -> np.ndarray:
    """(m, 3) camera-frame points -> (m, 2) px through OpenCV's pinhole + distortion model."""
    z = points_cam[:, 2]
    x, y = points_cam[:, 0] / z, points_cam[:, 1] / z
    xd, yd, _ = distort_normalised(x, y, dist_coeffs)
    K = camera_matrix
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)
