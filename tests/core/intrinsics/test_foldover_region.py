"""Fold-over is judged where the calibration is used: over the observed corners' region (+ OBSERVED_MARGIN),
alike for the fisheye and the pinhole models (a fisheye fit of the circular pair folded over at
90.8 deg off-axis, beyond every observed corner, and was rejected for it)."""

from __future__ import annotations

import numpy as np

from calibctl.config import LintThresholds
from calibctl.core.intrinsics import lens_checks
from calibctl.workflows.lint.lint import facts_from_document, lint_facts

SIZE = (960, 600)
K_FISH = np.array([[300.0, 0.0, 480.0], [0.0, 300.0, 300.0], [0.0, 0.0, 1.0]])
# theta_d = theta (1 + k1 theta^2) peaks where 1 + 3 k1 theta^2 = 0: at 80 deg off-axis, theta_d = 0.931
D_FOLD_80 = np.array([-1.0 / (3 * np.radians(80.0) ** 2), 0.0, 0.0, 0.0])
K_WIDE = np.array([[800.0, 0.0, 640.0], [0.0, 800.0, 480.0], [0.0, 0.0, 1.0]])
D_BARREL = np.array([-0.5, 0.0, 0.0, 0.0, 0.0])  # r_d peaks at r_u 0.8165, r_d 0.5443


def _ring(K: np.ndarray, radius_px: float, n: int = 36) -> np.ndarray:
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([K[0, 2] + radius_px * np.cos(a), K[1, 2] + radius_px * np.sin(a)])


def test_a_fisheye_folding_only_beyond_every_observed_corner_is_not_rejected():
    # judged out to the image, the 80 deg fold is found
    assert not lens_checks.check_equidistant_foldover(K_FISH, D_FOLD_80, SIZE).passed
    hull = lens_checks.observed_region_px([_ring(K_FISH, 200.0)])  # theta_d 0.667: about 45 deg off-axis
    f = lens_checks.check_equidistant_foldover(K_FISH, D_FOLD_80, SIZE, observed_px=hull)
    assert f.passed, f.message
    assert "observed region" in f.message


def test_a_fisheye_folding_inside_the_observed_region_is_rejected():
    hull = lens_checks.observed_region_px(
        [_ring(K_FISH, 290.0)]
    )  # theta_d 0.967 * 1.1, beyond the fold's 0.931
    f = lens_checks.check_equidistant_foldover(K_FISH, D_FOLD_80, SIZE, observed_px=hull)
    assert not f.passed
    assert (
        "stops increasing at 80.0 deg" in f.message and "folds over inside the observed region" in f.message
    )


def test_a_pinhole_model_is_judged_over_the_same_region():
    inside = lens_checks.observed_region_px(
        [_ring(K_WIDE, 800 * 0.5443 / (1 + lens_checks.OBSERVED_MARGIN) * 0.9)]
    )
    assert lens_checks.check_distortion_foldover(K_WIDE, D_BARREL, (1280, 960), observed_px=inside).passed
    beyond = lens_checks.observed_region_px(
        [_ring(K_WIDE, 800 * 0.53)]
    )  # grown 10 %: past the peak r_d 0.5443
    f = lens_checks.check_distortion_foldover(K_WIDE, D_BARREL, (1280, 960), observed_px=beyond)
    assert not f.passed and "observed region" in f.message


def test_the_region_never_reaches_beyond_the_image():
    everywhere = lens_checks.observed_region_px(
        [_ring(K_WIDE, 2000.0)]
    )  # a hull beyond the image judges the image
    f = lens_checks.check_distortion_foldover(K_WIDE, D_BARREL, (1280, 960), observed_px=everywhere)
    assert not f.passed and "farthest image corner" in f.message


def test_observed_region_is_the_convex_hull():
    pts = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [5.0, 5.0]])
    hull = lens_checks.observed_region_px([pts[:3], pts[3:]])
    assert hull is not None and len(hull) == 4 and [5.0, 5.0] not in hull.tolist()
    assert lens_checks.observed_region_px([pts[:2]]) is None


def _document(model: str, dist: np.ndarray, hull: np.ndarray | None) -> dict:
    doc = {
        "image_size": list(SIZE),
        "camera_matrix": K_FISH.tolist(),
        "dist_coeffs": dist.tolist(),
        "model": {"name": model},
    }
    if hull is not None:
        doc["observed_region_px"] = hull.tolist()
    return doc


def test_lint_reads_the_artifacts_observed_region():
    hull = lens_checks.observed_region_px([_ring(K_FISH, 200.0)])
    rule = "distortion-foldover"
    with_region = lint_facts(
        facts_from_document(_document("fisheye", D_FOLD_80, hull), "a"), LintThresholds()
    )
    without = lint_facts(facts_from_document(_document("fisheye", D_FOLD_80, None), "b"), LintThresholds())
    assert [f.severity for f in with_region if f.rule == rule] == []  # passed: no finding
    assert [f.severity for f in without if f.rule == rule] == ["error"]  # older artifacts: out to the image


def _box(K: np.ndarray, half_w: float, half_h: float) -> np.ndarray:
    cx, cy = K[0, 2], K[1, 2]
    return np.array(
        [
            [cx - half_w, cy - half_h],
            [cx + half_w, cy - half_h],
            [cx + half_w, cy + half_h],
            [cx - half_w, cy + half_h],
        ]
    )


def test_a_station_region_beyond_the_observed_one_is_judged_too():
    observed = lens_checks.observed_region_px([_ring(K_WIDE, 800 * 0.3)])  # well inside the peak r_d 0.5443
    assert lens_checks.check_distortion_foldover(K_WIDE, D_BARREL, (1280, 960), observed_px=observed).passed
    # a robot that looks out to r_d 0.61 (a box 960 x 200 px): the model folds over there
    wide = _box(K_WIDE, 480.0, 100.0)
    f = lens_checks.check_distortion_foldover(
        K_WIDE, D_BARREL, (1280, 960), observed_px=observed, required_px=wide
    )
    assert not f.passed and "folds over inside the station region" in f.message
    # a station region inside the observed one changes nothing: the union is the observed region
    small = _box(K_WIDE, 100.0, 50.0)
    f = lens_checks.check_distortion_foldover(
        K_WIDE, D_BARREL, (1280, 960), observed_px=observed, required_px=small
    )
    assert f.passed and "observed region" in f.message


def test_a_fisheye_is_judged_over_the_station_region_alike():
    observed = lens_checks.observed_region_px(
        [_ring(K_FISH, 200.0)]
    )  # about 45 deg: the 80 deg fold not judged
    assert lens_checks.check_equidistant_foldover(K_FISH, D_FOLD_80, SIZE, observed_px=observed).passed
    f = lens_checks.check_equidistant_foldover(
        K_FISH, D_FOLD_80, SIZE, observed_px=observed, required_px=_box(K_FISH, 290.0, 20.0)
    )
    assert not f.passed and "station region" in f.message


def test_lint_reads_the_artifacts_required_region():
    hull = lens_checks.observed_region_px([_ring(K_FISH, 200.0)])
    doc = _document("fisheye", D_FOLD_80, hull)
    doc["required_region_px"] = _box(K_FISH, 290.0, 20.0).tolist()
    found = lint_facts(facts_from_document(doc, "a"), LintThresholds())
    assert [f.severity for f in found if f.rule == "distortion-foldover"] == ["error"]
