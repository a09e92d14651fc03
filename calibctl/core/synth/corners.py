"""Seeded synthetic calibration sessions at the corner level (no images): ground truth for tests
and benchmarks of the solve.

Corners are projected with cv2.projectPoints from a known camera and board poses, then Gaussian
noise of ``noise_px`` per coordinate is added. Poses: the board is tilted by an angle drawn from
``tilt_deg`` about a random axis in its own plane, spun by a random angle about its normal, placed
at a depth drawn from ``distance_m`` so that its centre lands on a pixel drawn uniformly within
``centre_spread`` of the image half-size around the image centre. A pose whose corners leave the
image (minus ``margin_px``) is redrawn. Everything comes from numpy.random.default_rng(seed).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.board.board_geometry import chessboard_object_points

MAX_DRAWS_PER_VIEW = 1000


@dataclass(frozen=True)
class SyntheticSession:
    """A synthetic session with its ground truth.

    Attributes:
        object_points_per_view: V arrays (N, 3) float64 board frame, metres.
        image_points_per_view: V arrays (N, 2) float64 noisy corners, px.
        true_image_points_per_view: V arrays (N, 2) float64 noise-free corners, px.
        camera_matrix: (3, 3) true K. dist_coeffs: (n,) true distortion, OpenCV order.
        image_size: (width, height) px. rvecs, tvecs: (V, 3) true board->camera poses (m).
        tilt_deg: (V,) true tilt of each view.
    """

    object_points_per_view: tuple[np.ndarray, ...]
    image_points_per_view: tuple[np.ndarray, ...]
    true_image_points_per_view: tuple[np.ndarray, ...]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rvecs: np.ndarray
    tvecs: np.ndarray
    tilt_deg: np.ndarray


def _draw_pose(
    rng: np.random.Generator,
    K: np.ndarray,
    board_centre_m: np.ndarray,
    image_size: tuple[int, int],
    tilt_deg: tuple[float, float],
    distance_m: tuple[float, float],
    centre_spread: float,
) -> tuple[np.ndarray, np.ndarray, float]:
    azimuth = rng.uniform(0.0, 2 * np.pi)
    tilt = np.deg2rad(rng.uniform(*tilt_deg))
    R_tilt, _ = cv2.Rodrigues(np.array([np.cos(azimuth), np.sin(azimuth), 0.0]) * tilt)
    R_spin, _ = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))
    R = R_tilt @ R_spin
    w, h = image_size
    u = w / 2 + rng.uniform(-1, 1) * centre_spread * w / 2
    v = h / 2 + rng.uniform(-1, 1) * centre_spread * h / 2
    depth = rng.uniform(*distance_m)
    centre_cam = depth * np.linalg.solve(K, np.array([u, v, 1.0]))
    t = centre_cam - R @ board_centre_m
    rvec, _ = cv2.Rodrigues(R)
    return rvec.ravel(), t, float(np.rad2deg(tilt))


def synthesize_session(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    n_views: int,
    seed: int,
    noise_px: float = 0.2,
    tilt_deg: tuple[float, float] = (20.0, 40.0),
    distance_m: tuple[float, float] = (0.35, 0.6),
    centre_spread: float = 0.7,
    cols: int = 9,
    rows: int = 6,
    square_size_m: float = 0.025,
    margin_px: float = 5.0,
) -> SyntheticSession:
    """Draw a seeded synthetic session (see module docstring).

    Args:
        camera_matrix: (3, 3) px. dist_coeffs: (n,) OpenCV order. image_size: (width, height) px.
        n_views: board views. seed: RNG seed. noise_px: Gaussian sigma per coordinate, px.
        tilt_deg, distance_m: uniform ranges. centre_spread: 0 = board centred, 1 = anywhere.
        cols, rows, square_size_m: chessboard inner corners and square edge (m).

    Raises:
        ValueError: no pose fits the image after MAX_DRAWS_PER_VIEW draws (board too large).
    """
    rng = np.random.default_rng(seed)
    K = np.asarray(camera_matrix, dtype=np.float64)
    D = np.asarray(dist_coeffs, dtype=np.float64).ravel()
    obj = chessboard_object_points(cols, rows, square_size_m)
    centre = obj.mean(axis=0)
    w, h = image_size
    objs, noisy, clean, rvecs, tvecs, tilts = [], [], [], [], [], []
    for _ in range(n_views):
        for _draw in range(MAX_DRAWS_PER_VIEW):
            rvec, tvec, tilt = _draw_pose(rng, K, centre, image_size, tilt_deg, distance_m, centre_spread)
            proj, _ = cv2.projectPoints(obj, rvec, tvec, K, D)
            proj = proj.reshape(-1, 2)
            inside = (
                (proj[:, 0] >= margin_px)
                & (proj[:, 0] <= w - 1 - margin_px)
                & (proj[:, 1] >= margin_px)
                & (proj[:, 1] <= h - 1 - margin_px)
            )
            if inside.all():
                break
        else:
            raise ValueError(f"no board pose fits a {w}x{h} image after {MAX_DRAWS_PER_VIEW} draws")
        objs.append(obj.copy())
        clean.append(proj)
        noisy.append(proj + rng.normal(0.0, noise_px, size=proj.shape))
        rvecs.append(rvec)
        tvecs.append(tvec)
        tilts.append(tilt)
    return SyntheticSession(
        tuple(objs),
        tuple(noisy),
        tuple(clean),
        K.copy(),
        D.copy(),
        (int(w), int(h)),
        np.array(rvecs),
        np.array(tvecs),
        np.array(tilts),
    )
