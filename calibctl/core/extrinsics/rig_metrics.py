"""Geometric checks of a stereo pair on corners the solve did not see: epipolar error, rectified rows.

Both take the pair's relative pose ``T_b_a`` (maps camera a's frame into camera b's) and the two
cameras' intrinsics, and corners of the same board corner ids in both images.

- Epipolar error: corners are undistorted to ideal pixels (cv2.undistortPoints with P = K); with
  F = K_b^-T [t]x R K_a^-1 each corner's distance to the epipolar line of its partner, in both
  images. RMS and max over all those distances, px.
- Rectified vertical disparity: cv2.stereoRectify on the pair, both corner sets mapped through their
  rectification (R1/P1, R2/P2); the coordinate across the epipolar direction (v for a horizontal
  pair, u for a vertical one, as stereoRectify chooses) must agree. RMS and max, px.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.extrinsics.rig_problem import MemberIntrinsics


@dataclass(frozen=True)
class Rectification:
    """cv2.stereoRectify of a pair: R1, R2 (3, 3), P1, P2 (3, 4), Q (4, 4); horizontal or vertical."""

    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    horizontal: bool


def skew(t: np.ndarray) -> np.ndarray:
    x, y, z = np.asarray(t, dtype=np.float64).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def fundamental_matrix(T_b_a: np.ndarray, K_a: np.ndarray, K_b: np.ndarray) -> np.ndarray:
    """(3, 3) F with x_b^T F x_a = 0 for ideal (undistorted) pixels."""
    E = skew(T_b_a[:3, 3]) @ T_b_a[:3, :3]
    return np.asarray(np.linalg.inv(K_b).T @ E @ np.linalg.inv(K_a))


def essential_matrix(T_b_a: np.ndarray) -> np.ndarray:
    return np.asarray(skew(T_b_a[:3, 3]) @ T_b_a[:3, :3])


def ideal_pixels(points_px: np.ndarray, member: MemberIntrinsics) -> np.ndarray:
    """(N, 2) distorted px -> (N, 2) undistorted px of the same K."""
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 1, 2)
    out = cv2.undistortPoints(pts, member.camera_matrix, member.dist_coeffs, P=member.camera_matrix)
    return np.asarray(out).reshape(-1, 2)


def epipolar_distances_px(pts_a: np.ndarray, pts_b: np.ndarray, a: MemberIntrinsics, b: MemberIntrinsics,
                          T_b_a: np.ndarray) -> np.ndarray:
    """(2N,) distances of each corner to its partner's epipolar line (image b then image a), px."""
    F = fundamental_matrix(T_b_a, a.camera_matrix, b.camera_matrix)
    xa = np.column_stack([ideal_pixels(pts_a, a), np.ones(len(pts_a))])
    xb = np.column_stack([ideal_pixels(pts_b, b), np.ones(len(pts_b))])
    lines_b = xa @ F.T  # epipolar lines in image b
    lines_a = xb @ F  # epipolar lines in image a
    alg = np.sum(xb * lines_b, axis=1)
    d_b = np.abs(alg) / np.hypot(lines_b[:, 0], lines_b[:, 1])
    d_a = np.abs(alg) / np.hypot(lines_a[:, 0], lines_a[:, 1])
    return np.concatenate([d_b, d_a])


def rectify(a: MemberIntrinsics, b: MemberIntrinsics, T_b_a: np.ndarray) -> Rectification:
    """cv2.stereoRectify (CALIB_ZERO_DISPARITY, alpha -1) of the pair at camera a's image size."""
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(
        a.camera_matrix, a.dist_coeffs, b.camera_matrix, b.dist_coeffs, tuple(a.image_size),
        T_b_a[:3, :3], T_b_a[:3, 3].reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY)
    horizontal = abs(P2[0, 3]) >= abs(P2[1, 3])
    return Rectification(R1, R2, P1, P2, Q, bool(horizontal))


def rectified_cross_disparity_px(pts_a: np.ndarray, pts_b: np.ndarray, a: MemberIntrinsics, b: MemberIntrinsics,
                                 rect: Rectification) -> np.ndarray:
    """(N,) disparity across the epipolar direction after rectification (0 for a perfect pair), px."""
    ra = cv2.undistortPoints(np.asarray(pts_a, np.float64).reshape(-1, 1, 2), a.camera_matrix, a.dist_coeffs,
                             R=rect.R1, P=rect.P1).reshape(-1, 2)
    rb = cv2.undistortPoints(np.asarray(pts_b, np.float64).reshape(-1, 1, 2), b.camera_matrix, b.dist_coeffs,
                             R=rect.R2, P=rect.P2).reshape(-1, 2)
    axis = 1 if rect.horizontal else 0
    return np.asarray(ra[:, axis] - rb[:, axis])
