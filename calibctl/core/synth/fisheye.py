"""Seeded fisheye sessions at the corner level: an equidistant lens (up to 190 deg), circular or full-frame.

Lens: ``FisheyeCamera.from_fov`` puts the edge of the field of view (half-angle fov/2) on the image
circle (circular: radius just inside half the shorter side) or on the half-diagonal (full-frame), so
f = edge radius / theta_d(fov/2). Truth is ``project_equidistant`` (atan2, right beyond 90 deg).

Poses: the board centre is put on a ray drawn uniformly in solid angle up to ``max_view_deg`` off
the axis (at least a quarter of the views in its outer band, so the edge of the circle is used),
faced towards the camera, tilted 15-45 deg about a random in-plane axis and spun. A pose is redrawn
until every corner lies inside the image circle and the image (minus ``margin_px``) and within
MAX_SOLVE_THETA_RAD of the axis (cv2.fisheye cannot fit corners behind the camera plane).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from calibctl.core.board.board_geometry import chessboard_object_points
from calibctl.core.intrinsics.fisheye_model import (
    MAX_SOLVE_THETA_RAD,
    distort_theta,
    pixel_rays,
    project_equidistant,
)
from calibctl.core.synth.corners import MAX_DRAWS_PER_VIEW, SyntheticSession
from calibctl.core.synth.pinhole import padded_ray_map

# A mildly non-equidistant lens (k1..k4), the size real fisheye fits land at.
DEFAULT_FISHEYE_DIST = (0.02, -0.006, 0.001, -0.0002)


@dataclass(frozen=True)
class FisheyeCamera:
    """Equidistant Kannala-Brandt lens. K (3, 3) px, dist (4,) k1..k4, image_size (W, H),
    circle_radius_px: the image circle (None for full-frame), centred on the principal point."""

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    fov_deg: float
    circle_radius_px: float | None

    @classmethod
    def from_fov(
        cls,
        image_size: tuple[int, int],
        fov_deg: float,
        circular: bool = True,
        dist: tuple[float, ...] = DEFAULT_FISHEYE_DIST,
        aspect: float = 1.0,
    ) -> FisheyeCamera:
        w, h = image_size
        edge_px = (0.5 * min(w, h) - 4.0) if circular else 0.5 * float(np.hypot(w, h))
        f = edge_px / float(distort_theta(np.array(np.deg2rad(fov_deg) / 2.0), np.asarray(dist)))
        K = np.array([[f * aspect, 0.0, (w - 1) / 2.0 + 3.3], [0.0, f, (h - 1) / 2.0 - 2.1], [0.0, 0.0, 1.0]])
        return cls(
            K, np.asarray(dist, np.float64), (int(w), int(h)), float(fov_deg), edge_px if circular else None
        )

    def project(self, points_board_m: np.ndarray, T_cam_board: np.ndarray) -> np.ndarray:
        """(N, 3) board points, (4, 4) T_cam_board (m) -> (N, 2) px (the same call as
        PinholeCamera.project)."""
        T = np.asarray(T_cam_board, np.float64)
        return project_equidistant(
            np.asarray(points_board_m, np.float64) @ T[:3, :3].T + T[:3, 3], self.K, self.dist
        )

    def key(self) -> tuple[float, ...]:
        return (
            *self.K.ravel().tolist(),
            *self.dist.tolist(),
            float(self.image_size[0]),
            float(self.image_size[1]),
            float(self.circle_radius_px or 0.0),
        )

    def outside_circle(self) -> np.ndarray:
        """(H, W) bool: pixels outside the image circle (all False for a full-frame lens)."""
        w, h = self.image_size
        if self.circle_radius_px is None:
            return np.zeros((h, w), dtype=bool)
        u, v = np.meshgrid(np.arange(w), np.arange(h))
        return np.hypot(u - self.K[0, 2], v - self.K[1, 2]) > self.circle_radius_px

    def ray_map(self) -> tuple[np.ndarray, ...]:
        """Per-pixel unit ray (X, Y, Z), its derivatives wrt (u, v), and where it is valid (inside the image
        circle), as ``synth.padded_ray_map``. Unit rays, not X/Z, so a 190 deg lens renders the board
        behind the camera plane too (until 2026-11-23 pixels past 89 deg showed the background)."""
        return _fisheye_ray_map(self.key())

    def inside(self, px: np.ndarray, margin_px: float) -> np.ndarray:
        """(N,) bool: inside the image and the image circle, margin_px clear of both edges."""
        w, h = self.image_size
        ok = (
            (px[:, 0] >= margin_px)
            & (px[:, 0] <= w - 1 - margin_px)
            & (px[:, 1] >= margin_px)
            & (px[:, 1] <= h - 1 - margin_px)
        )
        if self.circle_radius_px is not None:
            ok &= (
                np.hypot(px[:, 0] - self.K[0, 2], px[:, 1] - self.K[1, 2])
                <= self.circle_radius_px - margin_px
            )
        return ok


@lru_cache(maxsize=2)
def _fisheye_ray_map(key: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    K, dist = np.array(key[:9]).reshape(3, 3), np.array(key[9:13])
    width, height, circle = int(key[13]), int(key[14]), key[15]
    u, v = np.meshgrid(
        np.arange(-1, width + 1, dtype=np.float64), np.arange(-1, height + 1, dtype=np.float64)
    )
    rays = pixel_rays(np.stack([u.ravel(), v.ravel()], axis=1), K, dist).reshape(height + 2, width + 2, 3)
    # unit rays, not X/Z: a 190 deg lens sees the board's outer squares behind the camera plane
    valid = rays[..., 2] > -np.cos(np.deg2rad(1.0))
    if circle > 0:
        valid &= np.hypot(u - K[0, 2], v - K[1, 2]) <= circle
    return padded_ray_map(rays[..., 0], rays[..., 1], rays[..., 2], valid)


def fisheye_poses(
    camera: FisheyeCamera,
    obj: np.ndarray,
    n_views: int,
    rng: np.random.Generator,
    distance_m: tuple[float, float],
    tilt_deg: tuple[float, float],
    max_view_deg: float | None,
    margin_px: float,
) -> list[np.ndarray]:
    """n_views (4, 4) T_cam_board staged as the module docstring says (obj: (N, 3) board points, m).

    Raises:
        ValueError: no pose fits after MAX_DRAWS_PER_VIEW draws.
    """
    centre = obj.mean(axis=0)
    limit = np.deg2rad(max_view_deg if max_view_deg is not None else min(camera.fov_deg / 2.0 - 8.0, 75.0))
    poses = []
    for k in range(n_views):
        outer = k % 4 == 0  # every fourth view in the outer band of the field
        for _ in range(MAX_DRAWS_PER_VIEW):
            off = float(
                np.arccos(rng.uniform(np.cos(limit), np.cos(0.75 * limit) if outer else 1.0))
            )  # uniform in solid angle
            rvec, tvec = _pose(rng, centre, off, float(rng.uniform(*distance_m)), tilt_deg)
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = cv2.Rodrigues(rvec)[0], tvec
            cam = obj @ T[:3, :3].T + tvec
            if (
                np.arctan2(np.hypot(cam[:, 0], cam[:, 1]), cam[:, 2]).max() < MAX_SOLVE_THETA_RAD
                and camera.inside(camera.project(obj, T), margin_px).all()
            ):
                break
        else:
            raise ValueError(
                f"no board pose fits the {camera.fov_deg:.0f} deg lens after {MAX_DRAWS_PER_VIEW} draws"
            )
        poses.append(T)
    return poses


def default_fisheye_distance_m(camera: FisheyeCamera, square_size_m: float) -> tuple[float, float]:
    """Board distances that keep its image size alike at any focal length (0.18-0.35 m at f = 320 px, 25
    mm)."""
    scale = float(camera.K[1, 1]) / 320.0 * square_size_m / 0.025
    return 0.18 * scale, 0.35 * scale


def _pose(
    rng: np.random.Generator,
    centre_m: np.ndarray,
    off_axis_rad: float,
    distance_m: float,
    tilt_deg: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    azimuth = rng.uniform(0.0, 2 * np.pi)
    ray = np.array(
        [np.sin(off_axis_rad) * np.cos(azimuth), np.sin(off_axis_rad) * np.sin(azimuth), np.cos(off_axis_rad)]
    )
    # face the camera: the board's z (out of the printed face) points back along the ray
    z = -ray
    x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    R_face = np.column_stack([x, np.cross(z, x), z])
    # the printed face points along board -z in cv convention: flip so the board faces the camera
    R_face = R_face @ np.diag([1.0, -1.0, -1.0])
    tilt_axis = rng.uniform(0.0, 2 * np.pi)
    R_tilt, _ = cv2.Rodrigues(
        np.array([np.cos(tilt_axis), np.sin(tilt_axis), 0.0]) * np.deg2rad(rng.uniform(*tilt_deg))
    )
    R_spin, _ = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))
    R = R_face @ R_tilt @ R_spin
    t = distance_m * ray - R @ centre_m
    rvec, _ = cv2.Rodrigues(R)
    return rvec.ravel(), t


def synthesize_fisheye_session(
    camera: FisheyeCamera,
    n_views: int,
    seed: int,
    noise_px: float = 0.2,
    distance_m: tuple[float, float] | None = None,
    tilt_deg: tuple[float, float] = (15.0, 45.0),
    max_view_deg: float | None = None,
    cols: int = 9,
    rows: int = 6,
    square_size_m: float = 0.025,
    margin_px: float = 4.0,
) -> SyntheticSession:
    """A seeded fisheye session (module docstring); dist_coeffs of the result are k1..k4.

    Raises:
        ValueError: no pose fits after MAX_DRAWS_PER_VIEW draws.
    """
    rng = np.random.default_rng(seed)
    obj = chessboard_object_points(cols, rows, square_size_m)
    distance = distance_m if distance_m is not None else default_fisheye_distance_m(camera, square_size_m)
    poses = fisheye_poses(camera, obj, n_views, rng, distance, tilt_deg, max_view_deg, margin_px)
    clean = [camera.project(obj, T) for T in poses]
    noisy = [p + rng.normal(0.0, noise_px, size=p.shape) for p in clean]
    rvecs = np.array([cv2.Rodrigues(T[:3, :3])[0].ravel() for T in poses])
    tilts = np.array([float(np.rad2deg(np.arccos(abs(T[2, 2])))) for T in poses])
    return SyntheticSession(
        tuple(obj.copy() for _ in poses),
        tuple(noisy),
        tuple(clean),
        camera.K.copy(),
        camera.dist.copy(),
        camera.image_size,
        rvecs,
        np.array([T[:3, 3] for T in poses]),
        tilts,
    )
