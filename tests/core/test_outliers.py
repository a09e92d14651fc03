"""Outlier views / corners and the drop-outliers re-solve, on seeded synthetic sessions."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.outliers import (
    CORNER_ABS_PX,
    flag_outliers,
    solve_dropping_outliers,
    view_outlier_threshold_px,
)
from calibctl.core.solve import solve_intrinsics
from calibctl.core.synthetic_corners import synthesize_session
from calibctl.errors import NumericalError

K_TRUE = np.array([[800.0, 0.0, 321.3], [0.0, 800.0, 238.7], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])
SIZE = (640, 480)
BAD_VIEW, BAD_CORNER_VIEW, BAD_CORNER = 6, 2, 17


@pytest.fixture(scope="module")
def clean():
    return synthesize_session(K_TRUE, D_TRUE, SIZE, n_views=16, seed=21)


@pytest.fixture(scope="module")
def corrupted(clean):
    """View 6 has 1.0 px corner noise instead of 0.2; corner 17 of view 2 is moved by 8 px."""
    rng = np.random.default_rng(3)
    img = [p.copy() for p in clean.image_points_per_view]
    img[BAD_VIEW] = clean.true_image_points_per_view[BAD_VIEW] + rng.normal(0, 1.0, img[BAD_VIEW].shape)
    img[BAD_CORNER_VIEW][BAD_CORNER] += (6.4, -4.8)
    return clean.object_points_per_view, img


def test_a_clean_session_has_no_outliers(clean):
    sol = solve_intrinsics(clean.object_points_per_view, clean.image_points_per_view, SIZE)
    report = flag_outliers(sol)
    assert report.outlier_views == ()
    assert report.outlier_corners == ()
    assert report.corner_sigma_robust_px == pytest.approx(0.2, rel=0.15)  # the injected noise


def test_noisy_view_and_moved_corner_are_flagged(corrupted):
    obj, img = corrupted
    sol = solve_intrinsics(obj, img, SIZE)
    ids = [np.arange(100, 154) for _ in obj]  # report board ids, not row positions
    report = flag_outliers(sol, corner_ids_per_view=ids)
    # one 8 px corner among 53 good ones lifts its view to ~1.1 px RMS: that view is flagged too
    assert report.outlier_views == (BAD_CORNER_VIEW, BAD_VIEW)
    worst = report.outlier_corners[0]
    assert (worst.view_index, worst.corner_id) == (BAD_CORNER_VIEW, 100 + BAD_CORNER)
    assert worst.residual_px == pytest.approx(8.0, abs=1.0)
    assert worst.residual_px == pytest.approx(np.hypot(worst.dx_px, worst.dy_px))
    assert worst.residual_px > CORNER_ABS_PX
    # the rest belong to the 1-px view (noise 5x the set's) or are neighbours the bad corner
    # dragged through its view's pose; no corner of a clean view is flagged
    assert {c.view_index for c in report.outlier_corners[1:]} == {BAD_VIEW, BAD_CORNER_VIEW}
    assert sum(c.view_index == BAD_CORNER_VIEW for c in report.outlier_corners) <= 2


def test_view_threshold_is_robust_to_the_outlier_itself():
    rms = np.array([0.27, 0.28, 0.29, 0.28, 0.27, 0.30, 5.0])
    threshold = view_outlier_threshold_px(rms)
    assert 0.30 < threshold < 0.5  # the 5 px view does not drag the threshold up to itself


def test_view_threshold_keeps_a_very_consistent_set_whole():
    rms = np.array([0.280, 0.281, 0.280, 0.281, 0.2805, 0.290])
    assert view_outlier_threshold_px(rms) == pytest.approx(1.5 * np.median(rms))


def test_drop_outliers_resolves_without_the_flagged_views(corrupted):
    obj, img = corrupted
    result = solve_dropping_outliers(obj, img, SIZE)
    assert result.dropped_views == (BAD_CORNER_VIEW, BAD_VIEW)
    assert result.kept_views == tuple(i for i in range(16) if i not in (BAD_CORNER_VIEW, BAD_VIEW))
    assert result.solution.n_views == 14 and result.first.n_views == 16
    assert result.solution.rms_px < result.first.rms_px
    direct = solve_intrinsics([obj[i] for i in result.kept_views], [img[i] for i in result.kept_views], SIZE)
    assert np.array_equal(direct.camera_matrix, result.solution.camera_matrix)


def test_drop_outliers_on_a_clean_set_drops_nothing(clean):
    result = solve_dropping_outliers(clean.object_points_per_view, clean.image_points_per_view, SIZE)
    assert result.dropped_views == () and result.solution is result.first


def test_drop_outliers_that_leaves_too_few_views_is_a_numerical_error(clean):
    rng = np.random.default_rng(4)
    obj = clean.object_points_per_view[:4]
    img = [p.copy() for p in clean.image_points_per_view[:4]]
    img[1] = clean.true_image_points_per_view[1] + rng.normal(0, 2.0, img[1].shape)
    with pytest.raises(NumericalError, match="dropping 1 outlier views leaves 3, fewer than the 4") as exc:
        solve_dropping_outliers(obj, img, SIZE, model="k1k2p1p2k3")
    assert "--drop-outliers" in exc.value.hint
