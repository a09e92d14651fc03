"""A stored lens as numbers, and the projections a comparison needs, with their Jacobians.

Pixels: OpenCV's convention (the top-left pixel's centre is (0, 0)). Rays: unit vectors in the camera
frame (z forward). Pinhole lenses project through cv2.projectPoints (distortion in OpenCV order),
fisheye lenses through cv2.fisheye.projectPoints (equidistant Kannala-Brandt, k1..k4); both return
the Jacobians on the intrinsics (in the stored covariance's parameter order, via
``core.intrinsics.covariance.intrinsic_columns``), on the pose and on the point.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from calibctl.core.intrinsics.covariance import intrinsic_columns
from calibctl.core.intrinsics.report_maps import unproject as unproject_pinhole
from calibctl.core.intrinsics.solution import IntrinsicsSolution
from calibctl.core.intrinsics.solve import is_fisheye

_K_NAMES = ("fx", "fy", "cx", "cy")
FISHEYE_PARAMETERS = ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")
ROUND_TRIP_PX = 1e-3  # a pixel whose unprojected ray does not project back within this is outside the model
FISHEYE_MAX_DEG = 85.0  # cv2.fisheye folds rays at 90 deg and beyond onto the front


@dataclass(frozen=True)
class Lens:
    """One camera's intrinsics and their covariance.

    Attributes:
        camera_matrix: (3, 3) float64 K, px. dist_coeffs: (n,) float64 (OpenCV order; fisheye: k1..k4).
        image_size: (W, H) px. fisheye: projected by cv2.fisheye.
        covariance: (p, p) float64 over ``parameters`` (px^2 for K entries, unitless^2 for distortion), or
            None when the calibration stores none. aspect: fx / fy when the solve tied them (then
            ``parameters`` lists fy for the tied focal length, and no fx).
        model: the lens model's name (for messages).
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    fisheye: bool = False
    covariance: np.ndarray | None = None
    parameters: tuple[str, ...] = ()
    aspect: float | None = None
    model: str = ""

    def scaled(self, scale: float) -> Lens:
        """The same lens in pixels ``scale`` times smaller (a 640x480 lens at 2.0 is the 1280x960 one).

        Pixel centres stay pixel centres: c' = s (c + 0.5) - 0.5; focal lengths scale by s, distortion
        (normalised coordinates) not at all; the covariance's K rows and columns scale by s.
        """
        K = np.array(self.camera_matrix, dtype=np.float64)
        K[0, 0] *= scale
        K[1, 1] *= scale
        K[0, 2] = scale * (K[0, 2] + 0.5) - 0.5
        K[1, 2] = scale * (K[1, 2] + 0.5) - 0.5
        size = (int(round(self.image_size[0] * scale)), int(round(self.image_size[1] * scale)))
        cov = None
        if self.covariance is not None:
            t = np.array([scale if n in _K_NAMES else 1.0 for n in self.parameters])
            cov = self.covariance * np.outer(t, t)
        return replace(self, camera_matrix=K, image_size=size, covariance=cov)


@dataclass(frozen=True)
class Projection:
    """Projection of M points through a lens after a pose (rvec, tvec).

    q_px: (M, 2). J_theta: (M, 2, p) on the lens's covariance parameters (None without a covariance).
    J_pose: (M, 2, 6) on (rvec rad, tvec in the points' unit). J_point: (M, 2, 3) on the point.
    valid: (M,) the point is in front of the lens (pinhole z > 0; fisheye within FISHEYE_MAX_DEG).
    """

    q_px: np.ndarray
    J_theta: np.ndarray | None
    J_pose: np.ndarray
    J_point: np.ndarray
    valid: np.ndarray


def project(
    lens: Lens,
    points: np.ndarray,
    rvec: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
    tvec: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
) -> Projection:
    """Project (M, 3) camera-frame points moved by (rvec, tvec) first: q = proj(R p + t)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(rvec, dtype=np.float64).reshape(3, 1)
    t = np.asarray(tvec, dtype=np.float64).reshape(3, 1)
    R, _ = cv2.Rodrigues(r)
    moved = pts @ R.T + t.ravel()
    K = np.asarray(lens.camera_matrix, dtype=np.float64)
    D = np.asarray(lens.dist_coeffs, dtype=np.float64)
    if lens.fisheye:
        q, J = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), r, t, K, D)
        J_pose = np.concatenate([J[:, 8:11], J[:, 11:14]], axis=1)
        J_int = J[:, :8]
        if lens.covariance is not None and tuple(lens.parameters) != FISHEYE_PARAMETERS:
            raise ValueError(f"covariance parameters {list(lens.parameters)} are not the fisheye model's")
        norm = np.linalg.norm(moved, axis=1)
        valid = moved[:, 2] > np.cos(np.deg2rad(FISHEYE_MAX_DEG)) * np.where(norm > 0, norm, 1.0)
    else:
        q, J = cv2.projectPoints(pts, r, t, K, D)
        J_pose = J[:, :6]
        J_int = None
        if lens.covariance is not None:
            free_k = (["fx"] if lens.aspect is not None else []) + [
                n for n in lens.parameters if n in _K_NAMES
            ]
            free_d = [n for n in lens.parameters if n not in _K_NAMES]
            J_int, names = intrinsic_columns(J, free_k, free_d, lens.aspect)
            if list(names) != list(lens.parameters):
                raise ValueError(
                    f"covariance parameters {list(lens.parameters)} do not match the model's {list(names)}"
                )
        valid = moved[:, 2] > 0
    m = len(pts)
    J_pose = J_pose.reshape(m, 2, 6)
    J_point = J_pose[:, :, 3:6] @ R  # d(R p + t)/dp = R
    J_theta = None if lens.covariance is None or J_int is None else J_int.reshape(m, 2, -1)
    q = q.reshape(-1, 2)
    return Projection(q, J_theta, J_pose, J_point, valid & np.isfinite(q).all(axis=1))


def unproject(lens: Lens, pixels_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 2) pixels -> (M, 3) unit rays and (M,) valid: the ray projects back onto the pixel.

    A pixel beyond where the distortion polynomial is monotonic (or a fisheye ray past FISHEYE_MAX_DEG)
    has no ray the model maps onto it; those are marked invalid, never compared.
    """
    px = np.asarray(pixels_px, dtype=np.float64).reshape(-1, 2)
    K = np.asarray(lens.camera_matrix, dtype=np.float64)
    D = np.asarray(lens.dist_coeffs, dtype=np.float64)
    if lens.fisheye:
        xy = cv2.fisheye.undistortPoints(px.reshape(-1, 1, 2), K, D).reshape(-1, 2)
    else:
        xy = unproject_pinhole(px, K, D)
    rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    back = project(replace(lens, covariance=None), rays)
    err = np.linalg.norm(back.q_px - px, axis=1)
    valid = back.valid & np.isfinite(rays).all(axis=1) & (err < ROUND_TRIP_PX)
    return rays, valid


def sample_pixels(image_size: tuple[int, int], grid: tuple[int, int]) -> np.ndarray:
    """Centres of a cols x rows grid of equal cells over the image: (rows * cols, 2) px, row-major."""
    w, h = image_size
    cols, rows = grid
    u = (np.arange(cols) + 0.5) * w / cols - 0.5
    v = (np.arange(rows) + 0.5) * h / rows - 0.5
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def lens_from_solution(solution: IntrinsicsSolution) -> Lens:
    """The Lens of an intrinsic solve (tests and benchmarks compare solves without a store)."""
    cov = solution.covariance
    matrix = None if cov is None or cov.covariance is None else np.asarray(cov.covariance, dtype=np.float64)
    return Lens(
        np.asarray(solution.camera_matrix, dtype=np.float64),
        np.asarray(solution.dist_coeffs, dtype=np.float64),
        (int(solution.image_size[0]), int(solution.image_size[1])),
        is_fisheye(solution.model),
        matrix,
        tuple(cov.names) if matrix is not None and cov is not None else (),
        solution.aspect_ratio,
        solution.model,
    )
