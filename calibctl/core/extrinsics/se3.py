"""Generic SE(3) / SO(3) helpers with frame-named arguments (numpy + OpenCV only).

Conventions (docs/conventions.md): ``T_a_b`` is a (4, 4) float64 homogeneous transform that maps
points expressed in frame ``b`` into frame ``a``; rotation vectors are axis * angle in radians;
quaternions are (w, x, y, z), Hamilton convention, unit norm; translations in metres.
"""

from __future__ import annotations

import cv2
import numpy as np

ORTHONORMAL_TOL = 1e-6  # |R^T R - I| and |det R - 1| above this: not a rotation (float32 round trips pass)


def skew(v: np.ndarray) -> np.ndarray:
    """(3,) -> (3, 3) cross-product matrix: skew(a) @ b == cross(a, b)."""
    x, y, z = (float(c) for c in np.asarray(v, np.float64).reshape(3))
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation_from_rotvec(rotvec_rad: np.ndarray | list[float]) -> np.ndarray:
    """(3,) axis * angle (rad) -> (3, 3) rotation matrix."""
    return cv2.Rodrigues(np.asarray(rotvec_rad, np.float64).reshape(3, 1))[0]


def rotvec_from_rotation(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (3,) axis * angle (rad), angle in [0, pi]: the SO(3) logarithm."""
    return cv2.Rodrigues(np.asarray(R, np.float64))[0].reshape(3)


def rotation_angle_rad(R: np.ndarray) -> float:
    """Angle (rad, 0..pi) of a (3, 3) rotation; well conditioned at small angles (unlike acos of the
    trace)."""
    return float(np.linalg.norm(rotvec_from_rotation(R)))


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle (degrees, 0..180) of a (3, 3) rotation, smooth down to zero (see rotvecs_from_rotations)."""
    return float(np.degrees(np.linalg.norm(rotvecs_from_rotations(np.asarray(R, np.float64)[:3, :3])[0])))


def rotation_from_quaternion(q_wxyz: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion (w, x, y, z) -> (3, 3) rotation. The caller checks the norm."""
    w, x, y, z = (float(c) for c in np.asarray(q_wxyz, np.float64).reshape(4))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (4,) unit quaternion (w, x, y, z) with w >= 0."""
    rotvec = rotvec_from_rotation(R)
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-300:
        return np.array([1.0, 0.0, 0.0, 0.0])
    q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * rotvec / angle])
    return q if q[0] >= 0 else -q


def quaternion_xyzw(R: np.ndarray) -> list[float]:
    """(3, 3) rotation -> [x, y, z, w] with w >= 0: ROS's order (geometry_msgs/Quaternion)."""
    w, x, y, z = (float(c) for c in quaternion_from_rotation(R))
    return [x, y, z, w]


def orthonormality_error(R: np.ndarray) -> float:
    """max(|R^T R - I|, |det R - 1|) of a (3, 3) matrix: 0 for a rotation, >= 2 for a reflection."""
    R = np.asarray(R, np.float64)
    return float(max(np.max(np.abs(R.T @ R - np.eye(3))), abs(np.linalg.det(R) - 1.0)))


def transform(R: np.ndarray, t_m: np.ndarray | list[float]) -> np.ndarray:
    """(3, 3) rotation + (3,) translation (m) -> (4, 4) T."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, np.float64)
    T[:3, 3] = np.asarray(t_m, np.float64).reshape(3)
    return T


def invert(T_a_b: np.ndarray) -> np.ndarray:
    """T_a_b -> T_b_a, using R^T rather than a general inverse."""
    R, t = T_a_b[:3, :3], T_a_b[:3, 3]
    return transform(R.T, -R.T @ t)


def relative(T_w_a0: np.ndarray, T_w_a1: np.ndarray) -> np.ndarray:
    """Motion of frame a between two poses in a world w: T_a0_a1 = inv(T_w_a0) @ T_w_a1."""
    return invert(T_w_a0) @ T_w_a1


def random_rotation(rng: np.random.Generator, angle_rad: float) -> np.ndarray:
    """A rotation by exactly ``angle_rad`` about a uniformly random axis."""
    axis = rng.standard_normal(3)
    return rotation_from_rotvec(axis / np.linalg.norm(axis) * angle_rad)


def rotvecs_from_rotations(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations -> (n, 3) rotation vectors (rad), vectorised.

    atan2(sin, cos) keeps small angles exact (residuals are small); angles within 0.1 rad of pi,
    where the antisymmetric part vanishes, go through OpenCV one by one.
    """
    R = np.asarray(R, np.float64).reshape(-1, 3, 3)
    v = 0.5 * np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    sin = np.linalg.norm(v, axis=1)
    cos = 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0)
    angle = np.arctan2(sin, cos)
    scale = np.where(sin > 1e-12, angle / np.maximum(sin, 1e-300), 1.0)
    out = v * scale[:, None]
    for i in np.flatnonzero(angle > np.pi - 0.1):
        out[i] = rotvec_from_rotation(R[i])
    return out


def rotations_from_rotvecs(rotvec_rad: np.ndarray) -> np.ndarray:
    """(n, 3) rotation vectors (rad) -> (n, 3, 3) rotations (Rodrigues' formula, vectorised)."""
    w = np.asarray(rotvec_rad, np.float64).reshape(-1, 3)
    angle = np.linalg.norm(w, axis=1)
    small = angle < 1e-8
    a = np.where(small, 1.0 - angle**2 / 6.0, np.sin(angle) / np.where(small, 1.0, angle))
    b = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(angle)) / np.where(small, 1.0, angle) ** 2)
    K = np.zeros((w.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)
