"""core.check.recheck on seeded synthetic corners: an unchanged camera passes, a changed one is named."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.check.recheck import (
    Reference,
    distance_ratio,
    holm_levels,
    ratio_limit,
    recheck,
    view_dispersion,
)
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.intrinsics.validation import validate_holdout
from calibctl.core.synth.corners import synthesize_session

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
D = np.array([-0.28, 0.09, 0.0, 0.0, 0.0])
SIZE = (640, 480)
NOISE_PX = 0.03  # per coordinate, about what calibctl's detector leaves on rendered boards


@pytest.fixture(scope="module")
def calibrated():
    s = synthesize_session(K, D, SIZE, 20, seed=7, noise_px=NOISE_PX)
    fit = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "k1k2")
    rep = validate_holdout(s.object_points_per_view, s.image_points_per_view, SIZE, "k1k2", fit=fit)
    h = rep.holdout
    n = sum(len(p) for p in s.image_points_per_view)
    ref = Reference(
        rep.holdout_rms_px,
        n,
        20,
        h.radius_edges_px,
        h.ring_rms_px,
        h.ring_counts,
        h.octant_rms_px,
        h.octant_counts,
    )
    sigma = {"focal": 0.3 / 800, "cx": 0.3, "cy": 0.3}
    return fit, ref, sigma


def _check(calibrated, camera: np.ndarray, seed: int, square_m: float = 0.025):
    fit, ref, sigma = calibrated
    s = synthesize_session(camera, D, SIZE, 10, seed=seed, noise_px=NOISE_PX, square_size_m=square_m)
    return recheck(
        s.object_points_per_view,
        s.image_points_per_view,
        fit.camera_matrix,
        fit.dist_coeffs,
        SIZE,
        ref,
        sigma,
    ), s


def test_an_unchanged_camera_passes_every_region_and_every_pull(calibrated):
    result, _ = _check(calibrated, K, seed=100)
    assert result.passed, (result.failed_regions, result.failed_shifts)
    assert result.regions[0].region == "overall" and result.regions[0].tested
    assert {r.region for r in result.regions} >= {"ring 5", "octant 7"}
    assert [p.name for p in result.shifts] == ["focal", "cx", "cy"]
    assert 0.7 < result.overall.ratio < result.overall.limit


def test_a_half_percent_focal_change_fails_on_the_focal_pull(calibrated):
    changed = K.copy()
    changed[0, 0] *= 1.005
    changed[1, 1] *= 1.005
    result, _ = _check(calibrated, changed, seed=101)
    assert not result.passed
    focal = result.shifts[0]
    assert not focal.passed and focal.shift == pytest.approx(0.005, abs=0.002)


def test_a_principal_point_shift_fails_on_cx_only(calibrated):
    changed = K.copy()
    changed[0, 2] += 4.0
    result, _ = _check(calibrated, changed, seed=102)
    failed = {p.name for p in result.failed_shifts}
    assert failed == {"cx"}
    assert result.shifts[1].shift == pytest.approx(4.0, abs=1.5)


def test_a_wrong_board_scale_leaves_no_residual_but_scales_the_distance(calibrated):
    # Seed chapter 0: printed 25 mm, registered 23 mm -> same pixels, every distance x0.92.
    fit, ref, sigma = calibrated
    s = synthesize_session(K, D, SIZE, 10, seed=103, noise_px=NOISE_PX, square_size_m=0.025)
    true_d = [
        float(np.linalg.norm(_R(r) @ s.object_points_per_view[i].mean(axis=0) + t))
        for i, (r, t) in enumerate(zip(s.rvecs, s.tvecs, strict=True))
    ]
    typo = [o * (0.023 / 0.025) for o in s.object_points_per_view]
    result = recheck(typo, s.image_points_per_view, fit.camera_matrix, fit.dist_coeffs, SIZE, ref, sigma)
    assert result.passed  # the residual cannot see it
    ratios = result.board_distance_m / np.array(true_d)
    assert np.allclose(ratios, 0.92, atol=0.004)


def _R(rvec: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(rvec, np.float64))[0]


def test_distance_ratio_is_median_over_reference_with_spread():
    ratio, spread = distance_ratio(np.array([0.59, 0.60, 0.61]), 0.5)
    assert ratio == pytest.approx(1.2) and spread == pytest.approx(0.02 / 0.60)


def test_the_ratio_limit_tightens_with_more_residuals_and_a_smaller_alpha():
    assert ratio_limit(1000, 2000, 0.01) < ratio_limit(100, 2000, 0.01)
    assert ratio_limit(1000, 2000, 0.001) > ratio_limit(1000, 2000, 0.01) > 1.0


def test_views_with_unequal_noise_widen_the_ratio_limit_and_equal_noise_does_not():
    rng = np.random.default_rng(3)
    equal = [rng.normal(0.0, 0.03, (54, 2)) for _ in range(10)]
    unequal = [rng.normal(0.0, s, (54, 2)) for s in (0.015, 0.02, 0.03, 0.05, 0.08) * 2]
    assert view_dispersion(equal) < 1.5
    assert view_dispersion(unequal) > 4.0
    assert ratio_limit(1000, 2000, 0.01, view_dispersion(unequal)) > ratio_limit(1000, 2000, 0.01) * 1.1


def test_holm_rejects_step_down_and_later_tests_keep_the_stopping_level():
    levels = holm_levels([0.0001, 0.2, 0.002, 0.03], 0.01)
    assert levels[0] == pytest.approx(0.01 / 4)  # smallest p: rejected at alpha / 4
    assert levels[2] == pytest.approx(0.01 / 3)  # second: rejected at alpha / 3
    assert levels[3] == pytest.approx(0.01 / 2)  # third (0.03 > 0.005): not rejected, the procedure stops
    assert levels[1] == pytest.approx(0.01 / 2)  # after the stop: the stopping level


@pytest.fixture(scope="module")
def fisheye_calibrated():
    from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

    camera = FisheyeCamera.from_fov((1280, 960), 170.0)
    s = synthesize_fisheye_session(camera, 18, seed=11, noise_px=0.1)
    fit = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, camera.image_size, "fisheye")
    rep = validate_holdout(
        s.object_points_per_view, s.image_points_per_view, camera.image_size, "fisheye", fit=fit
    )
    h = rep.holdout
    ref = Reference(
        rep.holdout_rms_px,
        sum(len(p) for p in s.image_points_per_view),
        18,
        h.radius_edges_px,
        h.ring_rms_px,
        h.ring_counts,
        h.octant_rms_px,
        h.octant_counts,
    )
    sigma = {"focal": fit.sigma["fx"] / fit.camera_matrix[0, 0], "cx": fit.sigma["cx"], "cy": fit.sigma["cy"]}
    return camera, fit, ref, sigma


def _fisheye_check(fisheye_calibrated, dcx_px: float, model: str = "fisheye"):
    from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

    camera, fit, ref, sigma = fisheye_calibrated
    K = camera.K.copy()
    K[0, 2] += dcx_px
    fresh = synthesize_fisheye_session(
        FisheyeCamera(K, camera.dist, camera.image_size, camera.fov_deg, camera.circle_radius_px),
        10,
        seed=12,
        noise_px=0.1,
    )
    return recheck(
        fresh.object_points_per_view,
        fresh.image_points_per_view,
        fit.camera_matrix,
        fit.dist_coeffs,
        camera.image_size,
        ref,
        sigma,
        model=model,
    )


def test_a_fisheye_calibration_is_checked_through_its_own_model(fisheye_calibrated):
    result = _fisheye_check(fisheye_calibrated, 0.0)
    assert result.passed, (result.failed_regions, result.failed_shifts)
    assert 0.7 < result.overall.ratio < 1.3
    # Through the pinhole projection (what check did before) the same views are nowhere near the model.
    pinhole = _fisheye_check(fisheye_calibrated, 0.0, model="k1k2")
    assert not pinhole.passed and pinhole.overall.ratio > 10


def test_a_fisheye_principal_point_shift_is_caught_on_cx(fisheye_calibrated):
    result = _fisheye_check(fisheye_calibrated, 4.0)
    assert {p.name for p in result.failed_shifts} == {"cx"}
    assert result.shifts[1].shift == pytest.approx(4.0, abs=1.5)
