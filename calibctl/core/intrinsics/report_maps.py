"""The numbers a calibration report draws, as pure functions of a stored calibration and its corners.

Projection uncertainty follows mrcal's show-projection-uncertainty in its simplest form: a pixel q is
unprojected to its ray with the solved intrinsics, the ray is projected again, and the intrinsic
covariance is propagated through that projection (Cov_q = J Sigma J^T, J = dq/d(intrinsics) with the
ray held fixed in the camera frame). Unlike mrcal it does not re-fit the camera frame to the board
poses a perturbed lens would imply, so it is an upper bound near the centre, where a shifted principal
point would mostly be absorbed by the extrinsics; the shape across the image is the same.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.intrinsics.covariance import intrinsic_columns
from calibctl.core.intrinsics.fisheye_model import MAX_SOLVE_THETA_RAD, pixel_rays

_K_NAMES = ("fx", "fy", "cx", "cy")
FISHEYE_CURVE_DEG = 75.0  # a fisheye's distortion curve stops here (the pinhole radius tan(theta) runs off)
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


def reprojection_residuals(
    object_points: np.ndarray,
    corners_px: np.ndarray,
    rvec: Sequence[float],
    tvec_m: Sequence[float],
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    fisheye: bool = False,
) -> np.ndarray:
    """observed - projected for one view under a stored pose and model (``fisheye``: cv2.fisheye's lens).

    Args: object_points (N, 3) float64 board frame, metres; corners_px (N, 2) float64; rvec, tvec_m:
    T_cam_board; camera_matrix (3, 3); dist_coeffs (n,). Returns (N, 2) float64 pixels.
    """
    obj = np.asarray(object_points, dtype=np.float64).reshape(-1, 1, 3)
    r, t = (
        np.asarray(rvec, dtype=np.float64).reshape(3, 1),
        np.asarray(tvec_m, dtype=np.float64).reshape(3, 1),
    )
    if fisheye:
        projected, _ = cv2.fisheye.projectPoints(obj, r, t, camera_matrix, dist_coeffs)
    else:
        projected, _ = cv2.projectPoints(obj, r, t, camera_matrix, dist_coeffs)
    return np.asarray(corners_px, dtype=np.float64) - projected.reshape(-1, 2)


def coverage_grid(corners_px: np.ndarray, image_size: tuple[int, int], cells: tuple[int, int]) -> np.ndarray:
    """Corner count per cell of a cols x rows grid over the image: (rows, cols) int64.

    corners_px: (N, 2) float64; image_size [W, H]; cells (cols, rows).
    """
    w, h = image_size
    cols, rows = cells
    pts = np.asarray(corners_px, dtype=np.float64).reshape(-1, 2)
    ci = np.clip((pts[:, 0] / w * cols).astype(np.int64), 0, cols - 1)
    ri = np.clip((pts[:, 1] / h * rows).astype(np.int64), 0, rows - 1)
    grid = np.zeros((rows, cols), dtype=np.int64)
    np.add.at(grid, (ri, ci), 1)
    return grid


def edge_gaps_px(corners_px: np.ndarray, image_size: tuple[int, int]) -> dict[str, float]:
    """Distance from each image edge to the nearest corner, pixels (left, right, top, bottom)."""
    pts = np.asarray(corners_px, dtype=np.float64).reshape(-1, 2)
    w, h = image_size
    return {
        "left": float(pts[:, 0].min()),
        "right": float(w - 1 - pts[:, 0].max()),
        "top": float(pts[:, 1].min()),
        "bottom": float(h - 1 - pts[:, 1].max()),
    }


def unproject(points_px: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) -> normalised ray coordinates (N, 2) (x/z, y/z) through the distortion model."""
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x: the iteration criteria live in their own call
        return cv2.undistortPointsIter(
            pts, camera_matrix, dist_coeffs, None, None, _UNDISTORT_CRITERIA
        ).reshape(-1, 2)
    return cv2.undistortPoints(
        pts, camera_matrix, dist_coeffs, R=None, P=None, criteria=_UNDISTORT_CRITERIA
    ).reshape(-1, 2)


@dataclass(frozen=True)
class UncertaintyMap:
    """Worst-direction one-sigma of projection across the image.

    u_px: (C,) and v_px: (R,) grid pixel coordinates; sigma_px: (R, C) float64 pixels (nan for a fisheye
    pixel beyond MAX_SOLVE_THETA_RAD off-axis, where cv2.fisheye has no projection).
    """

    u_px: np.ndarray
    v_px: np.ndarray
    sigma_px: np.ndarray


def projection_uncertainty(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    covariance: np.ndarray,
    parameters: Sequence[str],
    aspect: float | None,
    image_size: tuple[int, int],
    grid: tuple[int, int] = (32, 24),
    fisheye: bool = False,
    rotation_fit: np.ndarray | None = None,
) -> UncertaintyMap:
    """Propagate the intrinsic covariance to the projection of the ray through each grid pixel.

    Args:
        camera_matrix (3, 3), dist_coeffs (n,): the solved model. covariance (p, p) over ``parameters``
        (calibctl's order: fy stands for the tied focal length when ``aspect`` = fx/fy is set).
        image_size [W, H]; grid (cols, rows) sample points, pixel centres of equal cells.
        rotation_fit: (rows, cols) bool, or None. Given, each intrinsic perturbation's pixel shifts are
            taken less the camera rotation that best explains them over those grid points (mrcal's
            compensation in its rotation-only form: a shifted principal point the extrinsics absorb is not
            an error of where a ray lands relative to the others). None: the module docstring's upper bound.
    """
    w, h = image_size
    cols, rows = grid
    u = (np.arange(cols) + 0.5) * w / cols - 0.5
    v = (np.arange(rows) + 0.5) * h / rows - 0.5
    uu, vv = np.meshgrid(u, v)
    pixels = np.stack([uu.ravel(), vv.ravel()], axis=1)
    if fisheye:  # equidistant: cv2.fisheye's Jacobian columns are fx fy cx cy k1..k4, calibctl's order
        if list(parameters) != ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"]:
            raise ValueError(f"covariance parameters {list(parameters)} are not the fisheye model's")
        # rays through the equidistant model itself (right beyond 90 deg); cv2.fisheye projects only rays in
        # front of the camera plane, so pixels beyond MAX_SOLVE_THETA_RAD off-axis are nan (not known)
        rays = pixel_rays(pixels, camera_matrix, np.asarray(dist_coeffs, np.float64).ravel()[:4])
        known = np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]) < MAX_SOLVE_THETA_RAD
        points = np.where(known[:, None], rays / np.where(known, rays[:, 2], 1.0)[:, None], [0.0, 0.0, 1.0])
        _, J = cv2.fisheye.projectPoints(
            points.reshape(-1, 1, 3), np.zeros((3, 1)), np.zeros((3, 1)), camera_matrix, dist_coeffs
        )
        # columns: f (2), c (2), k (4), alpha, rvec (3), tvec (3)
        J_int = _less_rotation(J[:, :8], J[:, 9:12], rotation_fit, known.reshape(len(v), len(u)))
        umap = _worst_sigma(J_int, np.asarray(covariance, dtype=np.float64), u, v)
        return UncertaintyMap(u, v, np.where(known.reshape(len(v), len(u)), umap.sigma_px, np.nan))
    rays = unproject(pixels, camera_matrix, dist_coeffs)
    points = np.concatenate([rays, np.ones((len(rays), 1))], axis=1)
    _, J = cv2.projectPoints(points, np.zeros(3), np.zeros(3), camera_matrix, dist_coeffs)
    free_k = (["fx"] if aspect is not None else []) + [n for n in parameters if n in _K_NAMES]
    free_d = [n for n in parameters if n not in _K_NAMES]
    J_int, names = intrinsic_columns(J, free_k, free_d, aspect)
    if list(names) != list(parameters):
        raise ValueError(f"covariance parameters {list(parameters)} do not match the model's {list(names)}")
    J_int = _less_rotation(
        J_int,
        J[:, :3],
        rotation_fit,
        np.isfinite(J_int).all(axis=1).reshape(-1, 2).all(axis=1).reshape(len(v), len(u)),
    )
    return _worst_sigma(J_int, np.asarray(covariance, dtype=np.float64), u, v)


def _less_rotation(
    J_int: np.ndarray, J_rot: np.ndarray, fit: np.ndarray | None, usable: np.ndarray
) -> np.ndarray:
    """(2 R C, p) intrinsic columns less their least-squares fit by the (2 R C, 3) rotation columns over the
    grid points ``fit & usable`` ((R, C) bool); unchanged when ``fit`` is None or selects nothing."""
    if fit is None:
        return J_int
    rows = np.repeat((np.asarray(fit, bool) & usable).ravel(), 2)
    if rows.sum() < 6:
        return J_int
    coef, *_ = np.linalg.lstsq(J_rot[rows], J_int[rows], rcond=None)
    return J_int - J_rot @ coef


def _worst_sigma(J_int: np.ndarray, covariance: np.ndarray, u: np.ndarray, v: np.ndarray) -> UncertaintyMap:
    """(2 R C, p) projection Jacobian on the intrinsics -> the map of each pixel's worst-direction sigma."""
    Jq = J_int.reshape(-1, 2, J_int.shape[1])
    cov_q = np.einsum("mip,pq,mjq->mij", Jq, covariance, Jq)
    worst = np.linalg.eigvalsh(cov_q)[:, -1]
    return UncertaintyMap(u, v, np.sqrt(np.clip(worst, 0.0, None)).reshape(len(v), len(u)))


def distortion_curve(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    samples: int = 64,
    fisheye: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Radial displacement by the lens along the ray to the farthest image corner.

    Returns (r_px, displacement_px), each (samples,) float64: r_px the distorted distance from the
    principal point, displacement_px = r_px - the undistorted (pinhole) distance. Negative = barrel.
    """
    if fisheye:  # equidistant: theta from the axis to FISHEYE_CURVE_DEG (a pinhole has no image at 90 deg)
        theta = np.linspace(0.0, np.deg2rad(FISHEYE_CURVE_DEG), samples)
        k = np.asarray(dist_coeffs, dtype=np.float64).ravel()[:4]
        t2 = theta * theta
        r_px = camera_matrix[0, 0] * theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
        return r_px, r_px - camera_matrix[0, 0] * np.tan(theta)
    w, h = image_size
    c = camera_matrix[:2, 2]
    corners = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
    far = corners[np.argmax(np.linalg.norm(corners - c, axis=1))]
    ray_end = unproject(far[None, :], camera_matrix, dist_coeffs)[0]
    t = np.linspace(0.0, 1.0, samples)
    xy = t[:, None] * ray_end[None, :]
    projected, _ = cv2.projectPoints(
        np.concatenate([xy, np.ones((samples, 1))], axis=1),
        np.zeros(3),
        np.zeros(3),
        camera_matrix,
        dist_coeffs,
    )
    pinhole = xy * np.array([camera_matrix[0, 0], camera_matrix[1, 1]])
    r_px = np.linalg.norm(projected.reshape(-1, 2) - c, axis=1)
    return r_px, r_px - np.linalg.norm(pinhole, axis=1)
