"""The report's numbers: coverage, projection uncertainty (against a Monte-Carlo through plain
cv2.projectPoints), the distortion curve."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.intrinsics.report_maps import (
    coverage_grid,
    distortion_curve,
    edge_gaps_px,
    projection_uncertainty,
    unproject,
)

K = np.array([[800.0, 0.0, 319.5], [0.0, 800.0, 239.5], [0.0, 0.0, 1.0]])
D = np.array([-0.28, 0.09, 0.0, 0.0, 0.0])
SIZE = (640, 480)
NAMES = ["fy", "cx", "cy", "k1", "k2"]  # calibctl's k1k2 model: fx tied to fy
MC_TOLERANCE = 0.08  # 4000 draws: the sample std is within ~2 % (1 sigma); 8 % is 4 sigma


def test_coverage_grid_counts_every_corner_in_its_cell() -> None:
    pts = np.array([[0.0, 0.0], [639.9, 479.9], [330.0, 250.0], [331.0, 251.0]])
    grid = coverage_grid(pts, SIZE, (4, 3))
    assert grid.shape == (3, 4) and grid.sum() == 4
    assert grid[0, 0] == 1 and grid[2, 3] == 1 and grid[1, 2] == 2
    assert edge_gaps_px(pts, SIZE) == {
        "left": 0.0,
        "right": pytest.approx(-0.9),
        "top": 0.0,
        "bottom": pytest.approx(-0.9),
    }


def test_unproject_inverts_opencv_projection() -> None:
    rays = np.array([[0.0, 0.0], [0.3, -0.2], [-0.35, 0.25]])
    px, _ = cv2.projectPoints(np.c_[rays, np.ones(3)], np.zeros(3), np.zeros(3), K, D)
    assert np.allclose(unproject(px.reshape(-1, 2), K, D), rays, atol=1e-9)


def test_a_principal_point_sigma_alone_is_the_same_everywhere() -> None:
    cov = np.diag([0.0, 0.5**2, 0.0, 0.0, 0.0])
    m = projection_uncertainty(K, D, cov, NAMES, 1.0, SIZE, grid=(8, 6))
    assert m.sigma_px.shape == (6, 8) and np.allclose(m.sigma_px, 0.5)


def test_a_focal_sigma_alone_grows_from_zero_at_the_principal_point() -> None:
    cov = np.diag([1.0, 0.0, 0.0, 0.0, 0.0])
    m = projection_uncertainty(
        np.diag([800.0, 800.0, 1.0]) + np.array([[0, 0, 320.0], [0, 0, 240.0], [0, 0, 0]]),
        np.zeros(5),
        cov,
        NAMES,
        1.0,
        SIZE,
        grid=(64, 48),
    )
    centre = m.sigma_px[23:25, 31:33]
    assert centre.max() < 0.01 and m.sigma_px[0, 0] == pytest.approx(
        400.0 / 800.0, rel=0.02
    )  # r / f * sigma_f


def test_projection_uncertainty_matches_a_monte_carlo_through_plain_opencv() -> None:
    rng = np.random.default_rng(13)
    A = rng.normal(size=(5, 5)) * np.array([0.5, 0.4, 0.4, 0.003, 0.01])
    cov = A.T @ A / 5 + np.diag([0.2, 0.1, 0.1, 1e-6, 1e-5])
    m = projection_uncertainty(K, D, cov, NAMES, 1.0, SIZE, grid=(4, 3))
    uu, vv = np.meshgrid(m.u_px, m.v_px)
    rays = np.c_[unproject(np.c_[uu.ravel(), vv.ravel()], K, D), np.ones(uu.size)]
    draws = rng.multivariate_normal(np.array([800.0, 319.5, 239.5, -0.28, 0.09]), cov, size=4000)
    q = np.empty((len(draws), len(rays), 2))
    for i, (f, cx, cy, k1, k2) in enumerate(draws):
        Ki = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
        q[i] = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), Ki, np.array([k1, k2, 0.0, 0.0, 0.0]))[0][
            :, 0
        ]
    worst = [np.sqrt(np.linalg.eigvalsh(np.cov(q[:, j].T))[-1]) for j in range(len(rays))]
    assert np.allclose(m.sigma_px.ravel(), worst, rtol=MC_TOLERANCE)


def test_mismatched_covariance_names_are_refused() -> None:
    with pytest.raises(ValueError, match="do not match"):
        projection_uncertainty(K, D, np.eye(4), ["fx", "cx", "cy", "k1"], 1.0, SIZE)


def test_distortion_curve_is_flat_without_distortion_and_negative_for_barrel() -> None:
    r0, d0 = distortion_curve(K, np.zeros(5), SIZE)
    assert np.allclose(d0, 0.0, atol=1e-9) and r0[-1] == pytest.approx(np.hypot(319.5, 239.5), rel=1e-6)
    r, d = distortion_curve(K, np.array([-0.2, 0.0, 0.0, 0.0, 0.0]), SIZE)
    assert d[0] == 0.0 and np.all(d[1:] < 0) and np.all(np.diff(d) < 0)
    assert r[-1] == pytest.approx(np.hypot(319.5, 239.5), rel=1e-6)  # ends at the farthest image corner
