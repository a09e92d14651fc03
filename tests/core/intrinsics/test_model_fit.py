"""model-misfit: the fit RMS against a lens-free estimate of what the corner detector delivers."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.intrinsics.model_fit import (
    MISFIT_MIN_PX,
    MISFIT_RATIO,
    check_model_misfit,
    detector_rms_px,
    lens_floor_px,
    misfit,
    noise_floor_px,
)
from calibctl.core.intrinsics.outliers import solve_rejecting_corners
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.corners import synthesize_session
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session
from tests.core.intrinsics.test_solve_real import _natural, detect_all, model_points
from tests.datasets import LEFT_RIGHT, UDACITY, needs_datasets

NOISE_PX = 0.2
PER_CORNER = np.sqrt(2) * NOISE_PX  # per-corner (2-D) RMS of 0.2 px per coordinate


def _verdict(obj, img, size, model):
    r = solve_rejecting_corners(obj, img, size, model)
    return check_model_misfit(r.solution.rms_px, noise_floor_px(r.kept(obj), r.kept(img), size), model)


def _close_185_session():
    """A 185 deg circular fisheye, 12 x 9 board held close (seed 1): the curved field the 4x4 patch
    over-reads."""
    from calibctl.core.synth.fisheye import default_fisheye_distance_m

    size = (1032, 778)
    cam = FisheyeCamera.from_fov(size, 185.0, circular=True)
    near, far = default_fisheye_distance_m(cam, 0.025)
    s = synthesize_fisheye_session(
        cam,
        12,
        seed=1,
        max_view_deg=80.0,
        cols=12,
        rows=9,
        distance_m=(0.5 * near, 0.5 * far),
        noise_px=NOISE_PX,
    )
    return list(s.object_points_per_view), list(s.image_points_per_view), size


def test_the_floor_holds_on_a_curved_field_where_the_patch_over_reads():
    # measured: patch 1.681 px (5.9x the truth), lens floor 0.282 px (fisheye) for a per-corner 0.283 px
    obj, img, size = _close_185_session()
    assert detector_rms_px(obj, img) > 4 * PER_CORNER
    floor, model = lens_floor_px(obj, img, size)
    assert model == "fisheye" and floor == pytest.approx(PER_CORNER, rel=0.1)
    assert noise_floor_px(obj, img, size) == floor
    # the correct fisheye fit is not a misfit against it
    assert _verdict(obj, img, size, "fisheye").passed


@pytest.mark.parametrize(("fov_deg", "circular"), [(150.0, True), (185.0, True)])
def test_k1k2_on_a_fisheye_is_judged_against_the_noise_not_the_curvature(fov_deg, circular):
    # measured (1032x778, 15 views, seed 0): k1k2 fits 1.63 / 2.47 px, the patch reads 0.42 / 0.57 px
    # (ratio 3.9 / 4.7), the floor 0.28 px (ratio 5.8 / 8.7)
    size = (1032, 778)
    s = synthesize_fisheye_session(FisheyeCamera.from_fov(size, fov_deg, circular), 15, seed=0)
    obj, img = list(s.object_points_per_view), list(s.image_points_per_view)
    r = solve_rejecting_corners(obj, img, size, "k1k2")
    patch, floor = detector_rms_px(r.kept(obj), r.kept(img)), noise_floor_px(r.kept(obj), r.kept(img), size)
    assert floor < 0.75 * patch and floor == pytest.approx(PER_CORNER, rel=0.1)
    assert misfit(r.solution.rms_px, floor) and r.solution.rms_px / floor > 5.0


def test_the_lens_floor_is_none_when_no_lens_model_can_be_solved():
    obj, img, size = _close_185_session()
    assert lens_floor_px(obj[:2], img[:2], size) is None  # two views: neither fisheye nor rational solves
    assert noise_floor_px(obj[:2], img[:2], size) == detector_rms_px(obj[:2], img[:2])


def test_detector_noise_is_read_without_a_lens_model():
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    s = synthesize_session(K, np.array([-0.2814, 0.0977, 0, 0, 0]), (640, 480), 12, seed=3, noise_px=NOISE_PX)
    assert detector_rms_px(s.object_points_per_view, s.image_points_per_view) == pytest.approx(
        PER_CORNER, rel=0.15
    )
    clean = detector_rms_px(s.object_points_per_view, s.true_image_points_per_view)
    # a 4x4 patch of the strongly distorted seed lens is nearly quadratic: its curvature stays well below the
    # noise
    assert clean < 0.35 * PER_CORNER


def test_no_block_with_enough_corners_gives_no_estimate():
    obj = [np.zeros((5, 3)) + np.arange(5)[:, None] * [0.01, 0, 0]]
    assert detector_rms_px(obj, [np.zeros((5, 2))]) is None


@pytest.mark.parametrize(("fov_deg", "circular"), [(150.0, True), (190.0, True), (150.0, False)])
def test_k1k2_on_a_fisheye_fails_and_names_the_fisheye_model_which_passes(fov_deg, circular):
    cam = FisheyeCamera.from_fov((1280, 960), fov_deg, circular)
    s = synthesize_fisheye_session(cam, 15, seed=2)
    obj, img = list(s.object_points_per_view), list(s.image_points_per_view)
    bad = _verdict(obj, img, (1280, 960), "k1k2")
    assert not bad.passed and "--model fisheye" in bad.fix and f"limit {MISFIT_RATIO:.1f}x" in bad.message
    assert _verdict(obj, img, (1280, 960), "fisheye").passed


def test_non_square_pixels_fail_k1k2_and_the_hint_names_the_model_that_frees_fx_from_fy():
    """Frames resized in one axis (fx/fy = 1.06, as measured on real phone-video frames): k1k2 ties fx to
    fy and cannot fit them; the hint names opencv-default, which passes; fisheye's hint does not."""
    K = np.array([[848.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    s = synthesize_session(K, np.array([-0.2814, 0.0977, 0, 0, 0]), (640, 480), 18, seed=1, noise_px=NOISE_PX)
    obj, img = list(s.object_points_per_view), list(s.image_points_per_view)
    bad = _verdict(obj, img, (640, 480), "k1k2")
    assert not bad.passed and "--model opencv-default" in bad.fix and "ties fx to fy" in bad.fix
    assert _verdict(obj, img, (640, 480), "opencv-default").passed
    assert "opencv-default" not in check_model_misfit(2.0, 0.1, "fisheye").fix


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_good_pinhole_renders_pass(seed):
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    s = synthesize_session(K, np.array([-0.2814, 0.0977, 0, 0, 0]), (640, 480), 18, seed)
    assert _verdict(list(s.object_points_per_view), list(s.image_points_per_view), (640, 480), "k1k2").passed


def test_residuals_growing_with_radius_fail():
    finding = check_model_misfit(0.3, 0.28, "k1k2", inner_fit_rms_px=0.2, outer_fit_rms_px=0.9)
    assert not finding.passed and "grow with radius" in finding.message


@needs_datasets
@pytest.mark.parametrize(
    ("pattern", "size"),
    [
        ("opencv-left-right/left*.jpg", (640, 480)),
        ("opencv-left-right/right*.jpg", (640, 480)),
        ("udacity-camcal/calibration*.jpg", (1280, 720)),
    ],
)
def test_real_photo_sets_pass_under_k1k2(pattern, size):
    folder, glob = pattern.split("/")
    root = LEFT_RIGHT if folder == "opencv-left-right" else UDACITY
    views = detect_all(sorted(root.glob(glob), key=_natural))
    obj, img = [model_points()] * len(views), [c for _, c, _ in views]
    finding = _verdict(obj, img, size, "k1k2")
    assert finding.passed, finding.message
    # and the plain OpenCV solve of the same corners agrees on the fit RMS the rule judged
    import cv2

    rms, *_ = cv2.calibrateCamera(
        [o.astype(np.float32) for o in obj], [i.astype(np.float32) for i in img], size, None, None
    )
    assert rms < MISFIT_RATIO * detector_rms_px(obj, img)


def test_the_stored_floor_of_a_fisheye_fit_is_true_to_the_corner_noise() -> None:
    """An accepted fisheye fit recorded a floor 10x its corner noise: the lens-free patches over-read a curved
    field, and a fit under MISFIT_MIN_PX never asked the lens models. The floor never exceeds the fit."""
    camera = FisheyeCamera.from_fov((1280, 960), 170.0, circular=True)
    syn = synthesize_fisheye_session(camera, 18, 11, noise_px=0.1)
    obj, img = list(syn.object_points_per_view), list(syn.image_points_per_view)
    fit = solve_intrinsics(obj, img, (1280, 960), "fisheye", uncertainty=False)
    assert fit.rms_px < MISFIT_MIN_PX  # the short path: the lens-free read alone
    floor = noise_floor_px(obj, img, (1280, 960), float(fit.rms_px))
    true_px = 0.1 * 2**0.5  # per corner, as rms_px
    assert floor is not None and floor <= fit.rms_px and floor > 0.85 * true_px
