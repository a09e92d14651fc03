"""Numeric lint checks, on the seed's chapter-0 camera_front.yaml and constructed lenses."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.intrinsics.lens_checks import (
    ERROR,
    WARNING,
    check_aspect_ratio,
    check_distortion_foldover,
    check_finite,
    check_image_size,
    check_outer_ring_holdout,
    check_principal_point,
    check_sigma_fx,
    distort_normalised,
)

# seed chapter 0, camera_front.yaml: K fitted at 640x480, header says 1280x960
K_CH0 = np.array([[800.14, 0.0, 319.62], [0.0, 800.09, 240.31], [0.0, 0.0, 1.0]])
D_CH0 = np.array([-0.2814, 0.0977, 0.0001, -0.0002, -0.0163])
K_WIDE = np.array([[800.0, 0.0, 640.0], [0.0, 800.0, 480.0], [0.0, 0.0, 1.0]])


def test_chapter0_yaml_fails_principal_point_under_its_1280x960_header():
    f = check_principal_point(K_CH0, (1280, 960))
    assert (f.rule, f.severity, f.passed) == ("principal-point", ERROR, False)
    assert "(319.62, 240.31)" in f.message and "(320.4, 239.7) px" in f.message
    assert "limit (128.0, 96.0) px" in f.message
    assert "resolution the corners were detected at" in f.fix


def test_chapter0_K_passes_principal_point_at_640x480():
    f = check_principal_point(K_CH0, (640, 480))
    assert f.passed and f.fix is None


def test_principal_point_limit_is_strict_and_per_axis():
    K = K_CH0.copy()
    K[1, 2] = 240 + 48.0  # exactly 0.1 * H off
    assert not check_principal_point(K, (640, 480)).passed
    K[1, 2] = 240 + 47.9
    assert check_principal_point(K, (640, 480)).passed


def test_chapter0_coefficients_are_monotonic_at_640x480():
    f = check_distortion_foldover(K_CH0, D_CH0, (640, 480))
    assert f.passed, f.message
    assert f.rule == "distortion-foldover" and f.severity == ERROR


def test_strong_barrel_folds_over_at_a_wide_image():
    f = check_distortion_foldover(K_WIDE, np.array([-0.5, 0.0, 0.0, 0.0, 0.0]), (1280, 960))
    assert not f.passed
    # r_d = r (1 - 0.5 r^2) peaks at r = sqrt(2/3) = 0.8165 with r_d = 0.5443; corner r_d = 1.0009
    assert "stops increasing at r_u = 0.816" in f.message
    assert "r_d = 0.5443" in f.message and "r_d = 1.0009" in f.message
    assert "fewer coefficients" in f.fix


def test_the_same_barrel_is_fine_on_a_narrow_crop():
    K = np.array([[800.0, 0.0, 160.0], [0.0, 800.0, 120.0], [0.0, 0.0, 1.0]])
    assert check_distortion_foldover(K, np.array([-0.5, 0.0, 0.0, 0.0, 0.0]), (320, 240)).passed


def test_chapter0_coefficients_fold_over_when_read_at_1280x960():
    """The ch.0 lens polynomial was fitted out to r ~ 0.5; at 1280x960 the corner is r_d ~ 1.5."""
    f = check_distortion_foldover(K_CH0, D_CH0, (1280, 960))
    assert not f.passed and "r_d = 1.4990" in f.message


def test_strong_tangential_folds_where_the_radial_part_is_fine():
    f = check_distortion_foldover(K_WIDE, np.array([0.0, 0.0, 0.5, 0.0, 0.0]), (1280, 960))
    assert not f.passed
    assert "incl. tangential terms" in f.message and "Jacobian determinant" in f.message


def test_rational_denominator_term_can_fold_too():
    d = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.5, 0.0, 0.0])  # r / (1 + 1.5 r^2) peaks at r = 0.816
    f = check_distortion_foldover(K_WIDE, d, (1280, 960))
    assert not f.passed and "(r_d = 0.4082)" in f.message


def test_distortion_model_matches_opencv():
    import cv2

    d = np.array([-0.28, 0.09, 0.001, -0.002, 0.01, 0.02, -0.01, 0.005, 0.001, -0.002, 0.003, 0.0005])
    xy = np.random.default_rng(0).uniform(-0.6, 0.6, (50, 2))
    pts3 = np.column_stack([xy, np.ones(50)])
    proj, _ = cv2.projectPoints(pts3, np.zeros(3), np.zeros(3), np.eye(3), d)
    xd, yd, _ = distort_normalised(xy[:, 0], xy[:, 1], d)
    np.testing.assert_allclose(np.column_stack([xd, yd]), proj.reshape(-1, 2), atol=1e-12)


def test_sigma_fx_rule():
    assert check_sigma_fx(1.66).passed
    f = check_sigma_fx(5.4)
    assert not f.passed and f.message == "sigma(fx) = 5.400 px; limit 2.000 px" and "tilted" in f.fix
    refused = check_sigma_fx(None, "only 13 degrees of freedom")
    assert not refused.passed and "only 13 degrees of freedom" in refused.message
    assert not check_sigma_fx(float("nan")).passed
    assert not check_sigma_fx(1.9, max_px=1.5).passed


def test_sigma_fx_fix_names_the_corner_scatter_when_the_fit_rms_is_high():
    # udacity-camcal (k1k2, 16 views): sigma(fx) 2.27 px with a 0.889 px fit RMS; more tilted views alone
    # cannot reach the bar, sharper corners on a flat board can (sigma is linear in the scatter, seed ch.1)
    scattered = check_sigma_fx(2.27, fit_rms_px=0.889, detector_rms_px=0.508)
    assert not scattered.passed
    assert "0.889 px (the corners alone scatter 0.508 px)" in scattered.fix
    assert "flat" in scattered.fix and scattered.fix.endswith("tilted 20-40 deg in at least three directions")
    sharp = check_sigma_fx(2.27, fit_rms_px=0.3, detector_rms_px=0.25)
    assert sharp.fix == "capture more views tilted 20-40 deg in at least three directions"
    assert check_sigma_fx(1.5, fit_rms_px=0.889).fix is None  # a pass carries no fix


def test_outer_ring_holdout_rule():
    # seed ch.1: held-out outer ring doubled from 0.31 to 0.62 px while the fit said 0.261
    assert not check_outer_ring_holdout(0.62, 0.261).passed
    assert check_outer_ring_holdout(0.287, 0.281).passed
    f = check_outer_ring_holdout(1.1 * 0.3, 0.3)
    assert f.passed and "ratio 1.100, limit 1.10" in f.message
    assert not check_outer_ring_holdout(0.3, 0.0).passed


def test_the_outer_ring_fix_does_not_only_say_k1k2_which_may_be_the_model_already():
    # udacity-camcal (k1k2, the default) fails this rule by a hair on a non-flat paper board: the hint
    # used to say "solve with fewer coefficients (--model k1k2 or auto)" and nothing else.
    fix = check_outer_ring_holdout(1.0762, 0.9766).fix
    assert fix is not None and "fewer coefficients (--model k1k2 or auto)" in fix
    assert "with k1k2 already, capture more views with corners near the image edges" in fix
    assert "board is flat" in fix


def test_image_size_rule():
    assert check_image_size((640, 480), K_CH0).passed
    assert not check_image_size(None, K_CH0).passed
    assert not check_image_size((0, 480), K_CH0).passed
    f = check_image_size((320, 240), K_CH0)
    assert not f.passed and "does not lie inside the recorded 320x240 image" in f.message


def test_finite_rule_names_the_bad_quantities():
    f = check_finite({"camera_matrix": K_CH0, "dist_coeffs": D_CH0, "rms_px": 0.28})
    assert f.passed
    bad = check_finite({"camera_matrix": K_CH0, "dist_coeffs": np.array([np.nan, 0]), "rms_px": np.inf})
    assert not bad.passed and bad.message == "non-finite values in: dist_coeffs, rms_px"


def test_aspect_ratio_is_a_warning():
    assert check_aspect_ratio(K_CH0).passed
    K = K_CH0.copy()
    K[0, 0] = 1.02 * K[1, 1]
    f = check_aspect_ratio(K)
    assert (f.passed, f.severity) == (False, WARNING)
    assert "2.00 % from 1" in f.message


@pytest.mark.parametrize("dist", [np.zeros(4), np.zeros(5), np.zeros(8), np.zeros(14)])
def test_foldover_accepts_opencv_coefficient_lengths(dist):
    assert check_distortion_foldover(K_CH0, dist, (640, 480)).passed


def test_the_radial_fast_path_gives_the_same_bits_as_the_full_model():
    # lint --all runs the fold-over check once per serial; its radial search and the radial-only Jacobian
    # take shortcuts that must not change a single bit of what the check computes.
    from calibctl.core.intrinsics.lens_checks import _radial, distort_normalised

    rng = np.random.default_rng(3)
    r = np.arange(8001) * (2.5 / 40000)
    assert np.array_equal(r, np.linspace(0.0, 2.5, 40001)[:8001])
    for _ in range(50):
        d = np.zeros(12)
        d[[0, 1, 4, 5, 6, 7]] = rng.normal(0, 0.3, 6)
        xd, _, den = distort_normalised(r, np.zeros_like(r), d)
        rd, den_fast = _radial(r, d)
        assert np.array_equal(rd, xd) and np.array_equal(den, den_fast)


def test_outer_ring_ratio_counts_only_above_the_absolute_floor():
    # the good wide-angle solve: ratio 1.14 but only 0.017 px worse held-out
    small = check_outer_ring_holdout(0.142, 0.125)
    assert small.passed and "here 0.0170 px" in small.message
    # the same ratio 1.14 with a 0.5 px excess is over-fitting
    assert not check_outer_ring_holdout(4.0, 3.5).passed
    assert not check_outer_ring_holdout(0.142, 0.125, min_excess_px=0.01).passed


def test_a_k1k2_solve_is_never_told_to_re_solve_with_k1k2():
    outer = check_outer_ring_holdout(1.0762, 0.9766, model="k1k2").fix
    assert outer is not None and "--model k1k2" not in outer and "board is flat" in outer
    assert "fewer coefficients (--model k1k2 or auto)" in (
        check_outer_ring_holdout(1.0762, 0.9766, model="rational").fix or ""
    )
    fold = check_distortion_foldover(K_WIDE, np.array([-0.5, 0.0, 0.0, 0.0, 0.0]), (1280, 960), model="k1k2")
    assert (
        not fold.passed and "--model k1k2" not in (fold.fix or "") and "--model fisheye" in (fold.fix or "")
    )
    fold = check_distortion_foldover(
        K_WIDE, np.array([-0.5, 0.0, 0.0, 0.0, 0.0]), (1280, 960), model="k1k2k3"
    )
    assert "fewer coefficients (--model k1k2)" in (fold.fix or "")
