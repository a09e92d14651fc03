"""Geometric checks of a stereo pair on corners the solve did not see: epipolar error, rectified rows.

Both take the pair's relative pose ``T_b_a`` (maps camera a's frame into camera b's) and the two
cameras' intrinsics, and corners of the same board corner ids in both images.

- Epipolar error: corners are undistorted to ideal pixels (cv2.undistortPoints with P = K; a fisheye
  member: the angle of each ray to its partner's epipolar plane, times the focal length); with
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
from calibctl.core.intrinsics.fisheye_model import pixel_rays


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


def undistort(
    points_px: np.ndarray, member: MemberIntrinsics, R: np.ndarray | None = None, P: np.ndarray | None = None
) -> np.ndarray:
    """(N, 2) distorted px -> (N, 2) through the member's lens (cv2.undistortPoints, or cv2.fisheye's for a
    fisheye member), then R and P as OpenCV applies them."""
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 1, 2)
    if member.lens == "fisheye":
        D = np.asarray(member.dist_coeffs, np.float64).reshape(-1)[:4]
        out = cv2.fisheye.undistortPoints(
            pts, member.camera_matrix, D, R=np.eye(3) if R is None else R, P=np.eye(3) if P is None else P
        )
    else:
        out = cv2.undistortPoints(pts, member.camera_matrix, member.dist_coeffs, R=R, P=P)
    return np.asarray(out).reshape(-1, 2)


def ideal_pixels(points_px: np.ndarray, member: MemberIntrinsics) -> np.ndarray:
    """(N, 2) distorted px -> (N, 2) undistorted (pinhole) px of the same K."""
    return undistort(points_px, member, P=member.camera_matrix)


def unit_rays(points_px: np.ndarray, member: MemberIntrinsics) -> np.ndarray:
    """(N, 2) distorted px -> (N, 3) unit rays in the camera frame."""
    if member.lens == "fisheye":
        return pixel_rays(points_px, member.camera_matrix, member.dist_coeffs)
    rays = np.column_stack([undistort(points_px, member), np.ones(len(points_px))])
    return np.asarray(rays / np.linalg.norm(rays, axis=1, keepdims=True))


def _focal_px(member: MemberIntrinsics) -> float:
    return float(np.sqrt(member.camera_matrix[0, 0] * member.camera_matrix[1, 1]))


def epipolar_distances_px(
    pts_a: np.ndarray, pts_b: np.ndarray, a: MemberIntrinsics, b: MemberIntrinsics, T_b_a: np.ndarray
) -> np.ndarray:
    """(2N,) distances of each corner to its partner's epipolar line (image b then image a), px.

    With a fisheye member: the angle of each ray to its partner's epipolar plane times the camera's
    focal length (px at the image centre; ideal pixels would weigh a corner 70 deg off-axis 9x).
    """
    if a.lens == "fisheye" or b.lens == "fisheye":
        R, t = T_b_a[:3, :3], T_b_a[:3, 3]
        ra, rb = unit_rays(pts_a, a), unit_rays(pts_b, b)
        n_b = np.cross(t, ra @ R.T)  # epipolar plane of ray a, in b's frame
        n_a = np.cross(t, rb) @ R  # epipolar plane of ray b, in a's frame: R^T (t x r_b)
        d_b = np.arcsin(np.clip(np.abs(np.sum(n_b * rb, axis=1)) / np.linalg.norm(n_b, axis=1), 0.0, 1.0))
        d_a = np.arcsin(np.clip(np.abs(np.sum(n_a * ra, axis=1)) / np.linalg.norm(n_a, axis=1), 0.0, 1.0))
        return np.concatenate([d_b * _focal_px(b), d_a * _focal_px(a)])
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
    """cv2.stereoRectify (CALIB_ZERO_DISPARITY, alpha -1) of the pair at camera a's image size.

    With a fisheye member, cv2.stereoRectify without distortion: the rectifying rotations do not depend on
    the lens, and the projections are pinholes of the members' focal lengths. (cv2.fisheye.stereoRectify
    returned fx = 0 on the real sourishg pair: its new camera matrix is fitted to the image's corners, which
    lie outside a circular fisheye's image circle.)"""
    R, t = np.ascontiguousarray(T_b_a[:3, :3]), np.ascontiguousarray(T_b_a[:3, 3].reshape(3, 1))
    pinhole = a.lens != "fisheye" and b.lens != "fisheye"
    Da, Db = (m.dist_coeffs if pinhole else np.zeros(5) for m in (a, b))
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(
        a.camera_matrix, Da, b.camera_matrix, Db, tuple(a.image_size), R, t, flags=cv2.CALIB_ZERO_DISPARITY
    )
    horizontal = abs(P2[0, 3]) >= abs(P2[1, 3])
    return Rectification(R1, R2, P1, P2, Q, bool(horizontal))


def rectified_cross_disparity_px(
    pts_a: np.ndarray, pts_b: np.ndarray, a: MemberIntrinsics, b: MemberIntrinsics, rect: Rectification
) -> np.ndarray:
    """(N,) disparity across the epipolar direction after rectification (0 for a perfect pair), px.

    With a fisheye member: the rectified rays' angles about the baseline (the epipolar plane each lies in)
    times the rectified focal length, so a far off-axis corner is not magnified by the pinhole's tan.
    """
    if a.lens == "fisheye" or b.lens == "fisheye":
        ya, yb = unit_rays(pts_a, a) @ rect.R1.T, unit_rays(pts_b, b) @ rect.R2.T
        across = 1 if rect.horizontal else 0
        plane_a = np.arctan2(ya[:, across], ya[:, 2])
        plane_b = np.arctan2(yb[:, across], yb[:, 2])
        return np.asarray((plane_a - plane_b) * rect.P1[across, across])
    ra = undistort(pts_a, a, R=rect.R1, P=rect.P1)
    rb = undistort(pts_b, b, R=rect.R2, P=rect.P2)
    axis = 1 if rect.horizontal else 0
    return np.asarray(ra[:, axis] - rb[:, axis])
