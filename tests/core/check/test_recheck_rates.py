"""core.check.recheck's error rates on seeded sessions whose views have unequal detector noise, as rendered
photos do (blur, gain, tilt differ per view): few false fails, changes caught
(benchmarks/results/check.md)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.check.recheck import Reference, recheck
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.intrinsics.validation import validate_holdout
from calibctl.core.synth.pinhole import PinholeCamera
from calibctl.core.synth.scenes import scenario_poses

BOARD = BoardSpec.chessboard(9, 6, 0.025)
SIZE = (640, 480)
SESSIONS = 20
NOISE_MEDIAN_PX = 0.03  # per coordinate; each view's noise is this times a log-normal factor (sigma 0.5)


def _views(camera: PinholeCamera, n_views: int, rng: np.random.Generator) -> tuple[list, list]:
    obj = BOARD.object_points()
    img = []
    for T in scenario_poses("good", camera, BOARD, n_views, rng):
        rvec, _ = cv2.Rodrigues(T[:3, :3])
        proj, _ = cv2.projectPoints(obj, rvec, T[:3, 3], camera.K, camera.dist)
        noise_px = NOISE_MEDIAN_PX * float(np.exp(rng.normal(0.0, 0.5)))
        img.append(proj.reshape(-1, 2) + rng.normal(0.0, noise_px, (len(obj), 2)))
    return [obj] * len(img), img


def _camera(focal_scale: float = 1.0, dcx_px: float = 0.0) -> PinholeCamera:
    base = PinholeCamera.seed_reference(SIZE)
    K = base.K.copy()
    K[0, 0] *= focal_scale
    K[1, 1] *= focal_scale
    K[0, 2] += dcx_px
    return PinholeCamera(K, base.dist.copy(), SIZE)


@pytest.fixture(scope="module")
def reference():
    obj, img = _views(_camera(), 20, np.random.default_rng(10_000))
    fit = solve_intrinsics(obj, img, SIZE, "k1k2")
    h = validate_holdout(obj, img, SIZE, "k1k2", fit=fit).holdout
    ref = Reference(
        float(np.sqrt(np.nansum(h.ring_rms_px**2 * h.ring_counts) / h.ring_counts.sum())),
        int(h.ring_counts.sum()),
        20,
        h.radius_edges_px,
        h.ring_rms_px,
        h.ring_counts,
        h.octant_rms_px,
        h.octant_counts,
    )
    sigma = {"focal": fit.sigma["fx"] / fit.camera_matrix[0, 0], "cx": fit.sigma["cx"], "cy": fit.sigma["cy"]}
    return fit.camera_matrix, fit.dist_coeffs, ref, sigma


def _fails(reference, camera: PinholeCamera, seed0: int) -> int:
    K, D, ref, sigma = reference
    fails = 0
    for i in range(SESSIONS):
        obj, img = _views(camera, 10, np.random.default_rng(seed0 + i))
        fails += not recheck(obj, img, K, D, SIZE, ref, sigma).passed
    return fails


def test_an_unchanged_camera_with_unequal_view_noise_rarely_fails(reference):
    assert _fails(reference, _camera(), 20_000) <= 2


def test_a_half_percent_focal_change_is_caught_from_10_views(reference):
    assert _fails(reference, _camera(focal_scale=1.005), 21_000) >= 18


def test_a_4px_principal_point_shift_is_caught_from_10_views(reference):
    # 2 px from the solve's own "good" views is caught about 70 % of the time (benchmarks/results/check.md)
    assert _fails(reference, _camera(dcx_px=4.0), 22_000) >= 18
