"""Fisheye (equidistant Kannala-Brandt) lens: projection, focal guess, solve, sigma, held-out, outliers."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.intrinsics.fisheye_model import focal_guess_px, pixel_rays, project_equidistant
from calibctl.core.intrinsics.outliers import solve_rejecting_corners
from calibctl.core.intrinsics.solve import get_model, solve_intrinsics
from calibctl.core.intrinsics.validation import validate_holdout
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session
from calibctl.errors import NumericalError

SIZE = (1280, 960)
PARAMS = ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")
Z_LIMIT = 3.0  # the proof's "within 3 sigma"


def _truth(cam: FisheyeCamera) -> dict[str, float]:
    K, D = cam.K, cam.dist
    return dict(zip(PARAMS, (K[0, 0], K[1, 1], K[0, 2], K[1, 2], *D), strict=True))


def _estimate(sol) -> dict[str, float]:
    return dict(zip(PARAMS, (sol.fx, sol.fy, sol.cx, sol.cy, *sol.dist_coeffs), strict=True))


def test_equidistant_projection_matches_opencv_in_front_and_inverts_beyond_90_deg():
    cam = FisheyeCamera.from_fov(SIZE, 190.0, circular=True)
    rng = np.random.default_rng(0)
    front = rng.uniform([-1, -1, 0.2], [1, 1, 1.0], size=(50, 3))
    ours = project_equidistant(front, cam.K, cam.dist)
    theirs, _ = cv2.fisheye.projectPoints(front.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist)
    np.testing.assert_allclose(ours, theirs.reshape(-1, 2), atol=1e-8)
    # a 190 deg lens sees 5 deg behind the camera plane: the inverse must give those rays back
    theta = np.deg2rad(np.linspace(0.5, 94.5, 40))
    rays = np.stack([np.sin(theta), 0.3 * np.sin(theta), np.cos(theta)], axis=1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    back = pixel_rays(project_equidistant(rays, cam.K, cam.dist), cam.K, cam.dist)
    np.testing.assert_allclose(back, rays, atol=1e-9)
    assert (rays[:, 2] < 0).any()


@pytest.mark.parametrize(("fov_deg", "circular"), [(150.0, True), (170.0, False), (190.0, True)])
def test_focal_guess_lands_near_the_true_focal_length(fov_deg, circular):
    cam = FisheyeCamera.from_fov(SIZE, fov_deg, circular)
    s = synthesize_fisheye_session(cam, 12, seed=1)
    f = focal_guess_px(s.object_points_per_view, s.image_points_per_view, SIZE)
    assert f is not None and abs(f / cam.K[0, 0] - 1.0) < 0.1


@pytest.mark.parametrize(
    ("fov_deg", "circular", "seed"), [(150.0, True, 3), (170.0, False, 4), (190.0, True, 5)]
)
def test_fisheye_solve_recovers_every_parameter_within_three_sigma(fov_deg, circular, seed):
    cam = FisheyeCamera.from_fov(SIZE, fov_deg, circular)
    s = synthesize_fisheye_session(cam, 20, seed=seed, noise_px=0.2)
    sol = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "fisheye")
    assert sol.model == "fisheye" and sol.dist_coeffs.shape == (4,)
    # converged to the noise floor: per-corner RMS of 2-D Gaussian noise is sqrt(2) * 0.2 px
    assert 0.8 * np.sqrt(2) * 0.2 < sol.rms_px < 1.2 * np.sqrt(2) * 0.2
    truth, est = _truth(cam), _estimate(sol)
    assert set(sol.sigma) == set(PARAMS)
    z = {k: (est[k] - truth[k]) / sol.sigma[k] for k in PARAMS}
    assert all(abs(v) < Z_LIMIT for v in z.values()), z
    # the edge of the field is used: some view reaches past 85 % of the image circle / half-diagonal
    edge = cam.circle_radius_px or 0.5 * np.hypot(*SIZE)
    radii = [np.hypot(*(p - cam.K[:2, 2]).T).max() for p in s.image_points_per_view]
    assert max(radii) > 0.85 * edge


def test_fisheye_holdout_describes_the_fit_and_a_bad_corner_is_removed():
    cam = FisheyeCamera.from_fov(SIZE, 170.0, circular=True)
    s = synthesize_fisheye_session(cam, 15, seed=4)
    obj, img = list(s.object_points_per_view), [p.copy() for p in s.image_points_per_view]
    report = validate_holdout(obj, img, SIZE, "fisheye")
    assert report.model == "fisheye"
    assert report.holdout_rms_px < 1.2 * report.fit_rms_px
    img[3][10] += (6.0, -5.0)
    rejection = solve_rejecting_corners(obj, img, SIZE, "fisheye")
    assert [(c.view_index, c.corner_id) for c in rejection.rejected] == [(3, 10)]
    assert rejection.solution.rms_px < 0.35


def test_pinhole_k1k2_cannot_fit_a_fisheye_the_fisheye_model_can():
    cam = FisheyeCamera.from_fov(SIZE, 170.0, circular=True)
    s = synthesize_fisheye_session(cam, 15, seed=6)
    pinhole = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "k1k2")
    fisheye = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "fisheye")
    assert pinhole.rms_px > 5 * fisheye.rms_px


def test_a_view_with_scrambled_corners_is_named_when_the_solve_cannot_start():
    cam = FisheyeCamera.from_fov(SIZE, 170.0, circular=True)
    s = synthesize_fisheye_session(cam, 10, seed=7)
    img = [p.copy() for p in s.image_points_per_view]
    img[5] = img[5][np.random.default_rng(0).permutation(len(img[5]))]
    with pytest.raises(NumericalError, match=r"view 5") as exc:
        solve_intrinsics(s.object_points_per_view, img, SIZE, "fisheye")
    assert exc.value.exit_code == 2 and "view 5" in exc.value.hint


def test_fisheye_model_row():
    m = get_model("fisheye")
    assert m.kind == "fisheye" and not m.fx_tied_to_fy and m.n_free_intrinsic_params == 8
