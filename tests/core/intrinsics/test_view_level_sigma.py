"""The view-level sigma check (core/intrinsics/covariance.py): left alone on per-corner noise, the larger
sigma reported when every view carries an error of its own (docs/verdicts.md, "Sigmas that hold on real
data")."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.intrinsics.covariance import MAX_SIGMA_FACTOR, MIN_VIEWS_FOR_FACTOR
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.corners import synthesize_session

K_TRUE = np.array([[800.0, 0.0, 321.3], [0.0, 800.0, 238.7], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])
SIZE = (640, 480)


def _per_view_warp(points_px: list[np.ndarray], scale: float, seed: int) -> list[np.ndarray]:
    """Each view's corners moved by its own small random homography about the image centre (a per-view
    error the board pose cannot absorb: board warp, motion, a different zoom per frame)."""
    rng = np.random.default_rng(seed)
    centre = np.array([SIZE[0] / 2, SIZE[1] / 2])
    out = []
    for pts in points_px:
        H = np.eye(3)
        H[:2, :2] += rng.normal(0.0, scale, (2, 2))
        H[2, :2] = rng.normal(0.0, scale / 400.0, 2)
        xy1 = np.c_[np.asarray(pts, np.float64).reshape(-1, 2) - centre, np.ones(len(pts))] @ H.T
        out.append(xy1[:, :2] / xy1[:, 2:] + centre)
    return out


def _solve(seed: int, n_views: int, warp: float = 0.0):
    ses = synthesize_session(K_TRUE, D_TRUE, SIZE, n_views=n_views, seed=seed)
    img = ses.image_points_per_view if warp == 0 else _per_view_warp(ses.image_points_per_view, warp, seed)
    return solve_intrinsics(ses.object_points_per_view, img, SIZE, "k1k2")


@pytest.mark.parametrize("seed", range(8))
def test_per_corner_noise_is_left_alone(seed):
    sol = _solve(seed, n_views=15 + seed % 6)
    cov = sol.covariance
    assert cov is not None and cov.view_factor is not None
    assert 0.5 < cov.view_factor < MAX_SIGMA_FACTOR and not cov.inflated
    assert cov.jacobian_covariance is cov.covariance


def test_per_view_errors_inflate_the_reported_sigma():
    clean, warped = _solve(3, 18), _solve(3, 18, warp=2e-3)
    cov = warped.covariance
    assert cov is not None and cov.view_factor is not None
    assert cov.inflated and cov.view_factor > MAX_SIGMA_FACTOR and cov.n_views == 18
    # the reported sigma is the Jacobian one times the factor, larger than the Jacobian alone
    jacobian_fy = warped.sigma["fy"] / cov.view_factor
    assert warped.sigma["fy"] > 1.4 * jacobian_fy
    assert warped.sigma["fy"] > clean.sigma["fy"]
    assert np.allclose(np.sqrt(np.diag(cov.covariance)), [warped.sigma[n] for n in cov.names])
    assert cov.jacobian_covariance is not None  # kept beside it (the capture projection gate judges it)
    assert np.allclose(cov.jacobian_covariance * cov.view_factor**2, cov.covariance)


def test_the_larger_sigma_covers_the_error_the_jacobian_misses():
    """Over sessions with per-view errors the Jacobian's z is too wide; the reported one is not."""
    z_jac, z_rep = [], []
    for seed in range(12):
        sol = _solve(seed, 16, warp=2e-3)
        cov = sol.covariance
        assert cov is not None and cov.view_factor is not None and cov.inflated
        z_rep.append((sol.fy - K_TRUE[1, 1]) / sol.sigma["fy"])
        z_jac.append(z_rep[-1] * cov.view_factor)
    assert np.std(z_jac) > 1.5 * np.std(z_rep)
    assert np.std(z_rep) < 1.6


def test_too_few_views_compute_the_factor_but_keep_the_jacobian():
    sol = _solve(3, MIN_VIEWS_FOR_FACTOR - 1, warp=4e-3)
    cov = sol.covariance
    assert cov is not None and cov.view_factor is not None and not cov.inflated
    assert cov.n_views == MIN_VIEWS_FOR_FACTOR - 1
