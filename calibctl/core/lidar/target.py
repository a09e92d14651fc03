"""The board as the camera sees it: the backing board's plane, centre and corners from one image's pose.

The pattern frame is calibctl's board frame (core.board.board_geometry: origin at the first inner
corner, x along the columns, y along the rows, z out of the printed face). The backing board is a
rectangle ``backing_m`` = (width along x, height along y); the pattern's centre sits ``offset_m`` from
the backing board's centre (acfr: 2 mm, 0). The pose's uncertainty comes from the corner residuals:
Cov = s^2 (J^T J)^-1 over a left perturbation (dphi, dt) of T_cam_board, the same parameters the joint
solve (core.lidar.solve) perturbs, so it enters there as a prior without a change of variables.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.intrinsics.solve import project_points

MIN_PIXEL_SIGMA = 0.05  # a corner is never known better than this, whatever the fit says


@dataclass(frozen=True)
class BackingBoard:
    """The target: pattern geometry plus the backing board it is printed on (metres)."""

    cols: int
    rows: int
    square_m: float
    backing_m: tuple[float, float]
    offset_m: tuple[float, float] = (0.0, 0.0)

    def centre_in_pattern(self) -> np.ndarray:
        """(3,) the backing board's centre in the pattern frame."""
        return np.array(
            [
                (self.cols - 1) * self.square_m / 2 - self.offset_m[0],
                (self.rows - 1) * self.square_m / 2 - self.offset_m[1],
                0.0,
            ]
        )

    def corners_in_pattern(self) -> np.ndarray:
        """(4, 3) the backing board's corners in the pattern frame."""
        c = self.centre_in_pattern()
        w, h = self.backing_m[0] / 2, self.backing_m[1] / 2
        return np.array([c + [sx * w, sy * h, 0.0] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])

    def check_pattern_fits(self) -> str | None:
        """A sentence when the printed pattern (squares around the inner corners) overhangs the backing."""
        pattern = np.array([(self.cols + 1) * self.square_m, (self.rows + 1) * self.square_m])
        room = np.array(self.backing_m) - pattern - 2 * np.abs(np.array(self.offset_m))
        if (room < -1e-9).any():
            return (
                f"a {self.cols + 1} x {self.rows + 1}-square pattern ({pattern[0] * 1e3:.0f} x "
                f"{pattern[1] * 1e3:.0f} mm) does not fit on a {self.backing_m[0] * 1e3:.0f} x "
                f"{self.backing_m[1] * 1e3:.0f} mm backing board"
            )
        return None


@dataclass(frozen=True)
class CameraBoard:
    """One image's board: T_cam_board (4, 4) pattern -> camera, its 6x6 covariance over (dphi rad, dt m),
    the corner reprojection RMS in px."""

    T_cam_board: np.ndarray
    covariance: np.ndarray
    rms_px: float


def perturb(T: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """T with a left perturbation: R' = exp(delta[:3]) R, t' = t + delta[3:] ((6,) rad, m)."""
    out = T.copy()
    out[:3, :3] = se3.rotation_from_rotvec(delta[:3]) @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + delta[3:]
    return out


def pose_covariance(
    T_cam_board: np.ndarray,
    object_points_m: np.ndarray,
    corners_px: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str,
) -> tuple[np.ndarray, float]:
    """(6, 6) covariance of (dphi, dt) from the corner residuals, and their RMS in px.

    Args:
        object_points_m: (N, 3) pattern points matched to ``corners_px`` (N, 2) px.
    """
    obj = np.asarray(object_points_m, np.float64).reshape(-1, 3)

    def project(T: np.ndarray) -> np.ndarray:
        rvec = se3.rotvec_from_rotation(T[:3, :3])
        return project_points(obj, rvec, T[:3, 3].copy(), camera_matrix, dist_coeffs, model).reshape(-1)

    base = project(T_cam_board)
    resid = base - np.asarray(corners_px, np.float64).reshape(-1)
    J = np.empty((base.size, 6))
    for k in range(6):
        step = np.zeros(6)
        step[k] = 1e-6
        J[:, k] = (project(perturb(T_cam_board, step)) - base) / 1e-6
    dof = max(base.size - 6, 1)
    sigma_px = max(float(np.sqrt(resid @ resid / dof)), MIN_PIXEL_SIGMA)
    cov = sigma_px**2 * np.linalg.inv(J.T @ J)
    return cov, float(np.sqrt(np.mean(resid.reshape(-1, 2) ** 2) * 2))


def plane_in_camera(T_cam_board: np.ndarray) -> tuple[np.ndarray, float]:
    """The board plane in the camera frame: (unit normal pointing away from the camera, distance m)."""
    n = T_cam_board[:3, 2].copy()
    d = float(n @ T_cam_board[:3, 3])
    return (n, d) if d >= 0 else (-n, -d)
