"""Outlier views / corners and the drop-outliers re-solve, on seeded synthetic sessions."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.intrinsics.outliers import (
    CORNER_ABS_PX,
    flag_outliers,
    solve_dropping_outliers,
    solve_rejecting_corners,
    view_outlier_threshold_px,
)
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.corners import synthesize_session
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
    # nothing else: the 1-px view is noisy throughout (the view rule's business, not its corners'), and
    # the bad corner's neighbours are judged against their own view's noise
    assert report.outlier_corners[1:] == ()


def test_view_threshold_is_robust_to_the_outlier_itself():
    rms = np.array([0.27, 0.28, 0.29, 0.28, 0.27, 0.30, 5.0])
    threshold = view_outlier_threshold_px(rms)
    assert 0.30 < threshold < 0.6  # the 5 px view does not drag the threshold up to itself


def test_view_threshold_keeps_a_very_consistent_set_whole():
    rms = np.array([0.280, 0.281, 0.280, 0.281, 0.2805, 0.290])
    assert view_outlier_threshold_px(rms) == pytest.approx(2.0 * np.median(rms))
    # and a view far under a sub-pixel detector's noise is never an outlier, however tight the set
    assert view_outlier_threshold_px(np.array([0.03, 0.03, 0.031, 0.03, 0.15])) == pytest.approx(0.2)


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


def test_the_moved_corner_is_removed_from_the_solve_by_default(corrupted, clean):
    obj, img = corrupted
    ids = [np.arange(54) for _ in obj]
    first = solve_intrinsics(obj, img, SIZE)
    rejection = solve_rejecting_corners(obj, img, SIZE, "k1k2", ids)
    rejected = {(c.view_index, c.corner_id) for c in rejection.rejected}
    assert (BAD_CORNER_VIEW, BAD_CORNER) in rejected
    worst = next(
        c for c in rejection.rejected if (c.view_index, c.corner_id) == (BAD_CORNER_VIEW, BAD_CORNER)
    )
    assert worst.residual_px == pytest.approx(8.0, abs=0.5)  # its residual under the final solve
    assert not rejection.keep_masks[BAD_CORNER_VIEW][BAD_CORNER]
    assert rejection.solution.n_views == len(obj)  # corners go, views stay
    # no corner of a view that is clean is removed, besides the bad corner itself
    assert {v for v, _ in rejected} <= {BAD_CORNER_VIEW, BAD_VIEW}
    assert rejection.solution.per_view_rms_px[BAD_CORNER_VIEW] < 0.5 * first.per_view_rms_px[BAD_CORNER_VIEW]


def test_with_one_bad_corner_the_solve_is_the_solve_without_it(clean):
    obj, img = clean.object_points_per_view, [p.copy() for p in clean.image_points_per_view]
    img[BAD_CORNER_VIEW][BAD_CORNER] += (6.4, -4.8)
    rejection = solve_rejecting_corners(obj, img, SIZE)
    assert [(c.view_index, c.corner_id) for c in rejection.rejected] == [(BAD_CORNER_VIEW, BAD_CORNER)]
    assert rejection.rounds == 2
    keep = np.arange(54) != BAD_CORNER
    without = [o[keep] if k == BAD_CORNER_VIEW else o for k, o in enumerate(obj)]
    direct = solve_intrinsics(
        without, [p[keep] if k == BAD_CORNER_VIEW else p for k, p in enumerate(img)], SIZE
    )
    assert np.array_equal(direct.camera_matrix, rejection.solution.camera_matrix)
    assert rejection.solution.rms_px < solve_intrinsics(obj, img, SIZE).rms_px


def test_a_clean_session_loses_no_corner(clean):
    rejection = solve_rejecting_corners(clean.object_points_per_view, clean.image_points_per_view, SIZE)
    assert rejection.rejected == () and rejection.rounds == 1
    assert all(m.all() for m in rejection.keep_masks)


def test_a_corner_whose_view_cannot_spare_it_stays_in_the_solve(clean):
    obj = [o.copy() for o in clean.object_points_per_view]
    img = [p.copy() for p in clean.image_points_per_view]
    keep = [0, 8, 45, 53]  # a 4-corner view: the solver's minimum
    obj[3], img[3] = obj[3][keep], img[3][keep]
    img[3][1] += (0.0, 9.0) if img[3][1][1] < 400 else (0.0, -9.0)
    rejection = solve_rejecting_corners(obj, img, SIZE)
    assert rejection.keep_masks[3].all()
    assert 3 not in {c.view_index for c in rejection.rejected}
