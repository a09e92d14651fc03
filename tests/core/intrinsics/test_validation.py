"""k-fold held-out validation, ring/octant breakdown, on seeded synthetic sessions."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.intrinsics.validation import (
    fold_assignment,
    radius_ring_edges_px,
    residual_breakdown,
    validate_holdout,
)
from calibctl.core.synth.corners import synthesize_session
from calibctl.errors import EXIT_CANNOT_RUN, NumericalError
from calibctl.workflows.camera.verdict_lanes import verdict_lanes

K_TRUE = np.array([[800.0, 0.0, 321.3], [0.0, 800.0, 238.7], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])
SIZE = (640, 480)
OUTER_RATIO_MAX = 1.1  # the lint limit


@pytest.fixture(scope="module")
def good():
    ses = synthesize_session(K_TRUE, D_TRUE, SIZE, n_views=18, seed=31)
    return ses, validate_holdout(ses.object_points_per_view, ses.image_points_per_view, SIZE, "k1k2")


def test_fold_assignment_interleaves_views():
    assert fold_assignment(12, 3).tolist() == [0, 1, 2, 3, 4, 0, 1, 2, 3, 4, 0, 1]
    assert fold_assignment(4, 3).tolist() == [0, 1, 2, 3]


def test_fold_assignment_grows_to_leave_one_out_when_training_sets_get_too_small():
    folds = fold_assignment(6, 5)  # 5 folds would train on 4 views; rational needs 5
    assert folds.tolist() == [0, 1, 2, 3, 4, 5]


def test_too_few_views_to_hold_any_out():
    with pytest.raises(NumericalError, match="held-out validation needs at least 4 views, got 3") as exc:
        fold_assignment(3, 3)
    assert exc.value.exit_code == EXIT_CANNOT_RUN


def test_good_session_held_out_is_close_to_fit(good):
    _, report = good
    assert report.n_folds == 5
    assert 1.0 <= report.holdout_rms_px / report.fit_rms_px < 1.05
    assert report.outer_ratio < OUTER_RATIO_MAX
    assert report.holdout_outer_rms_px == report.holdout.ring_rms_px[-1]
    # every fold's K is close to the others: the solve is stable under leaving views out
    assert np.ptp(report.fold_camera_matrices[:, 0, 0]) < 5.0


def test_rings_hold_a_fifth_of_the_corners_each_and_match_between_fit_and_holdout(good):
    ses, report = good
    n = sum(len(p) for p in ses.image_points_per_view)
    assert report.fit.ring_counts.sum() == n and report.fit.octant_counts.sum() == n
    assert np.all(np.abs(report.fit.ring_counts - n / 5) <= 1)
    np.testing.assert_array_equal(report.fit.ring_counts, report.holdout.ring_counts)
    np.testing.assert_array_equal(report.fit.radius_edges_px, report.holdout.radius_edges_px)
    assert np.all(report.fit.octant_counts > 0)


def test_breakdown_puts_points_in_the_right_ring_and_octant():
    pts = [np.array([[330.0, 240.0], [320.0, 250.0], [310.0, 240.0], [320.0, 130.0], [420.0, 340.0]])]
    res = [np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 0.0], [0.0, 4.0], [3.0, 4.0]])]
    edges = np.array([5.0, 50.0, 100.0, 120.0])
    b = residual_breakdown(pts, res, (320.0, 240.0), (640, 480), edges)
    # radii 10, 10, 10, 110, 141 -> rings 1, 1, 1, 3, 4
    assert b.ring_counts.tolist() == [0, 3, 0, 1, 1]
    assert b.ring_rms_px[1] == pytest.approx(np.sqrt((1 + 4 + 9) / 3))
    assert np.isnan(b.ring_rms_px[0]) and b.outer_rms_px == pytest.approx(5.0)
    # angles 0, 90, 180, -90 (=270), 45 deg around (320, 240) -> octants 0, 2, 4, 6, 1
    assert b.octant_counts.tolist() == [1, 1, 1, 0, 1, 0, 1, 0]


def test_ring_edges_are_quantiles_of_the_corner_radii():
    pts = [np.column_stack([np.arange(1.0, 101.0), np.zeros(100)])]
    edges = radius_ring_edges_px(pts, (0.0, 0.0))
    np.testing.assert_allclose(edges, [20.8, 40.6, 60.4, 80.2])


def test_holdout_is_deterministic(good):
    ses, report = good
    again = validate_holdout(ses.object_points_per_view, ses.image_points_per_view, SIZE, "k1k2")
    assert again.holdout_rms_px == report.holdout_rms_px
    assert all(
        np.array_equal(a, b)
        for a, b in zip(again.holdout_residuals_px, report.holdout_residuals_px, strict=True)
    )


@pytest.mark.parametrize("jobs", [2, 4])
@pytest.mark.parametrize("model", ["k1k2", "k1k2p1p2k3"])
def test_folds_solved_on_lanes_equal_the_sequential_run_bit_for_bit(good, model, jobs):
    """The folds run on 2 or 4 lanes; every number must be exactly what one thread gives, and OpenCV's
    process-global thread count must be what it was before."""
    ses, _ = good
    threads_before = cv2.getNumThreads()
    args = (ses.object_points_per_view, ses.image_points_per_view, SIZE, model)
    with verdict_lanes(1) as one:
        sequential = validate_holdout(*args, lanes=one)
    with verdict_lanes(jobs) as lanes:
        parallel = validate_holdout(*args, lanes=lanes)
    assert cv2.getNumThreads() == threads_before
    assert np.array_equal(parallel.fold_of_view, sequential.fold_of_view)
    assert np.array_equal(parallel.fold_camera_matrices, sequential.fold_camera_matrices)
    assert (
        len(parallel.holdout_residuals_px)
        == len(sequential.holdout_residuals_px)
        == len(ses.image_points_per_view)
    )
    assert all(
        np.array_equal(a, b)
        for a, b in zip(parallel.holdout_residuals_px, sequential.holdout_residuals_px, strict=True)
    )
    assert np.array_equal(parallel.holdout_per_view_rms_px, sequential.holdout_per_view_rms_px)
    assert parallel.holdout_rms_px == sequential.holdout_rms_px
    for a, b in ((parallel.holdout, sequential.holdout), (parallel.fit, sequential.fit)):
        assert np.array_equal(a.ring_rms_px, b.ring_rms_px) and np.array_equal(
            a.octant_rms_px, b.octant_rms_px
        )


def _fold_starts(monkeypatch) -> list[tuple[np.ndarray | None, np.ndarray | None]]:
    """(K, distortion) each fold solve of validate_holdout starts from, recorded as they are asked."""
    from calibctl.core.intrinsics import validation

    starts: list[tuple[np.ndarray | None, np.ndarray | None]] = []
    real = validation.solve_intrinsics

    def spy(*a, **k):
        starts.append((a[4], k.get("initial_dist")))
        return real(*a, **k)

    monkeypatch.setattr(validation, "solve_intrinsics", spy)
    return starts


@pytest.mark.parametrize("model", ["k1k2", "k1k2p1p2k3"])
def test_folds_started_from_the_fit_reach_the_minimum_of_folds_started_cold(good, model, monkeypatch):
    """A warm fold starts from the fit's K and distortion, and lands where the cold fold lands: the same
    minimum, to well inside what any recorded figure prints (6 significant digits)."""
    ses, _ = good
    args = (ses.object_points_per_view, ses.image_points_per_view, SIZE, model)
    fit = solve_intrinsics(*args)
    cold = validate_holdout(*args, fit=fit)
    starts = _fold_starts(monkeypatch)
    warm = validate_holdout(*args, fit=fit, warm=True)
    assert len(starts) == cold.n_folds >= 3
    assert all(K is fit.camera_matrix and D is fit.dist_coeffs for K, D in starts)
    np.testing.assert_allclose(warm.fold_camera_matrices, cold.fold_camera_matrices, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(warm.holdout_per_view_rms_px, cold.holdout_per_view_rms_px, rtol=1e-6)
    assert warm.holdout_rms_px == pytest.approx(cold.holdout_rms_px, rel=1e-7)


def test_rational_folds_start_cold_even_when_asked_to_start_from_the_fit(monkeypatch):
    """Rational folds started from the fit can settle in another minimum (solve.starts_warm): each fold is
    the cold solve of its views (its own k1k2 start), as without ``warm``."""
    ses = synthesize_session(K_TRUE, D_TRUE, SIZE, n_views=8, seed=31)
    args = (ses.object_points_per_view, ses.image_points_per_view, SIZE, "rational")
    fit = solve_intrinsics(*args, uncertainty=False)
    starts = _fold_starts(monkeypatch)
    report = validate_holdout(*args, fit=fit, warm=True)
    assert len(starts) == report.n_folds >= 3
    assert all(K is None and D is None for K, D in starts)


def _sparse_outer_ring_session(seed: int):
    """Six small central boards far from the camera and two boards close up reaching the image
    edges: few corners in the outer ring, all of them in two views."""
    central = synthesize_session(
        K_TRUE, D_TRUE, SIZE, n_views=6, seed=seed, distance_m=(0.8, 1.1), centre_spread=0.2
    )
    wide = synthesize_session(
        K_TRUE, D_TRUE, SIZE, n_views=2, seed=100 + seed, distance_m=(0.3, 0.4), centre_spread=1.0
    )
    return (
        central.object_points_per_view + wide.object_points_per_view,
        central.image_points_per_view + wide.image_points_per_view,
    )


def test_overfit_distortion_shows_in_the_outer_ring_held_out():
    """Seed ch.1 failure mode B: with k3 and tangential free and few corners in the outer ring,
    held-out outer-ring RMS grows beyond the fit's; the 2-coefficient model stays near 1.
    Over 12 seeded sessions (ratios vary a lot session to session, so the medians are compared)."""
    simple, overfit = [], []
    for seed in range(12):
        obj, img = _sparse_outer_ring_session(seed)
        simple.append(validate_holdout(obj, img, SIZE, "k1k2").outer_ratio)
        overfit.append(validate_holdout(obj, img, SIZE, "k1k2p1p2k3").outer_ratio)
    assert np.median(overfit) > OUTER_RATIO_MAX
    assert np.median(overfit) > np.median(simple) + 0.05
    assert np.median(simple) < OUTER_RATIO_MAX
    assert sum(o > s for o, s in zip(overfit, simple, strict=True)) >= 8


def test_a_fold_that_cannot_be_solved_names_the_fold():
    """View 4 keeps only its first row (collinear corners): every training set containing it fails.
    The fit is passed in (solved on the intact views) so the failure happens inside a fold."""
    ses = synthesize_session(K_TRUE, D_TRUE, SIZE, n_views=6, seed=32)
    fit = solve_intrinsics(ses.object_points_per_view, ses.image_points_per_view, SIZE, "k1k2")
    obj, img = list(ses.object_points_per_view), list(ses.image_points_per_view)
    obj[4], img[4] = obj[4][:9], img[4][:9]
    for jobs in (1, 2, 4):  # on lanes too, the error names the first failing fold
        with (
            verdict_lanes(jobs) as lanes,
            pytest.raises(
                NumericalError, match=r"held-out fold 0 \(views \[0, 5\] held out\): OpenCV could not"
            ),
        ):
            validate_holdout(obj, img, SIZE, "k1k2", fit=fit, lanes=lanes)


def test_blas_runs_on_one_thread_inside_the_block_and_gets_its_threads_back():
    import cv2  # noqa: F401  (its bundled OpenBLAS is one of the libraries limited)
    from threadpoolctl import threadpool_info, threadpool_limits

    from calibctl.core.blas_threads import single_threaded_blas

    def counts() -> list[int]:
        return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]

    if not counts():
        pytest.skip("no BLAS library threadpoolctl can see in this environment")
    with threadpool_limits(limits=2):  # a known count to come back to, whatever the machine's cores
        before = counts()
        with single_threaded_blas():
            assert counts() == [1] * len(before)
            with single_threaded_blas():  # nested: still 1, and leaving it gives nothing back early
                pass
            assert counts() == [1] * len(before)
        assert counts() == before


def _stuck(sol, factor):
    """The same solve reporting a worse minimum than it found (a full solve stuck where its folds were
    not)."""
    import dataclasses

    return dataclasses.replace(sol, rms_px=sol.rms_px * factor)


def test_a_full_solve_worse_than_its_folds_is_re_solved_from_the_folds_intrinsics(good):
    from calibctl.core.intrinsics.validation import agree_with_folds

    ses, _ = good
    obj, img = ses.object_points_per_view, ses.image_points_per_view
    fit = solve_intrinsics(obj, img, SIZE, "k1k2")
    report = validate_holdout(obj, img, SIZE, "k1k2", fit=fit)
    same_fit, same_report = agree_with_folds(obj, img, SIZE, fit, report)
    assert same_fit is fit and same_report is report  # consistent: nothing to do
    new_fit, new_report = agree_with_folds(obj, img, SIZE, _stuck(fit, 3.0), report)
    assert new_fit.rms_px == pytest.approx(fit.rms_px, rel=1e-6)
    assert new_fit.rms_px <= new_report.holdout_rms_px and new_report.fit_rms_px == new_fit.rms_px


def test_a_full_solve_that_stays_worse_than_its_folds_is_refused(good, monkeypatch):
    import dataclasses

    from calibctl.core.intrinsics import validation
    from calibctl.core.intrinsics.validation import agree_with_folds

    ses, _ = good
    obj, img = ses.object_points_per_view, ses.image_points_per_view
    fit = solve_intrinsics(obj, img, SIZE, "k1k2")
    report = validate_holdout(obj, img, SIZE, "k1k2", fit=fit)
    optimistic = dataclasses.replace(report, holdout_rms_px=0.5 * fit.rms_px)
    # the folds stay better whichever way the re-solve from their K lands (OpenCV 4.x may land a hair lower)
    monkeypatch.setattr(validation, "validate_holdout", lambda *args, **kwargs: optimistic)
    with pytest.raises(NumericalError, match=r"worse than its held-out folds .* different minima") as exc:
        agree_with_folds(obj, img, SIZE, fit, optimistic)
    assert exc.value.exit_code == EXIT_CANNOT_RUN and "--model" in exc.value.hint
