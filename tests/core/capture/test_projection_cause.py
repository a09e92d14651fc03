"""The projection gate names the cause first: when a camera that changed during the session, a lens model
that cannot describe a wide lens, a board that is not flat or a board that moved from view to view explains
the uncertainty, that cause and its fix come before the views' hint (seeded corners; a tight threshold makes
every gate here fail, so only the named cause differs)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.capture.projection_gate import Region, cause_first, projection_gate, solve_for_gate
from calibctl.core.intrinsics.report_maps import projection_uncertainty
from calibctl.core.synth.corners import synthesize_session
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
D = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])
SIZE = (640, 480)
TIGHT_PX = 0.01  # below any session's sigma: the gate fails, its hint is what is judged
REGION = Region("image")


def _judged(obj, img, size, model):
    solution = solve_for_gate(obj, img, size, model)
    gate = projection_gate(solution, size, REGION, TIGHT_PX)
    assert not gate.passed and gate.reason == "projection.uncertain"
    return gate, cause_first(gate, solution, obj, img, size, REGION, TIGHT_PX)


def _pinhole(K_after: np.ndarray, seed: int):
    a = synthesize_session(K, D, SIZE, 12, seed, noise_px=0.05)
    b = synthesize_session(K_after, D, SIZE, 12, seed + 1000, noise_px=0.05)
    return [*a.object_points_per_view, *b.object_points_per_view], [
        *a.image_points_per_view,
        *b.image_points_per_view,
    ]


def test_a_camera_that_changed_is_named_before_the_views() -> None:
    K_after = K.copy()
    K_after[:2, :2] *= 1.01
    gate, named = _judged(*_pinhole(K_after, 21), SIZE, "k1k2")
    assert named.reason == "projection.camera_changed"
    assert named.hint is not None and named.hint.startswith("the camera changed during the session (focal")
    assert named.hint.endswith(f"then, if it is still uncertain: {gate.hint}")
    assert named.value == gate.value  # the verdict is the gate's; only its cause is named


def test_one_camera_keeps_the_views_hint() -> None:
    gate, named = _judged(*_pinhole(K, 22), SIZE, "k1k2")
    assert named == gate


@pytest.mark.parametrize("model", ["k1k2"])
def test_a_wide_lens_solved_with_a_pinhole_model_is_told_the_model(model: str) -> None:
    camera = FisheyeCamera.from_fov((1280, 960), 150.0, circular=False)
    syn = synthesize_fisheye_session(camera, 18, 5, noise_px=0.1)
    obj, img = list(syn.object_points_per_view), list(syn.image_points_per_view)
    gate, named = _judged(obj, img, (1280, 960), model)
    assert named.reason == "projection.lens_model"
    assert named.hint is not None and named.hint.startswith(
        "calibrate with --model fisheye (or --model auto)"
    )
    assert "the fisheye model fits its corners to" in named.message
    fisheye_gate, fisheye_named = _judged(obj, img, (1280, 960), "fisheye")  # the right model: no such cause
    assert fisheye_named.reason == "projection.uncertain"


def _bent(seed: int, bows_m: list[tuple[float, float]]):
    """A pinhole session whose board bows by (w_x, w_y) m at its centre in each view (parabolic cylinders
    over the board's extent); the solve is told the board is flat."""
    syn = synthesize_session(K, D, SIZE, len(bows_m), seed, noise_px=0.05)
    rng = np.random.default_rng(seed)
    obj, img = [], []
    for o, r, t, (wx, wy) in zip(syn.object_points_per_view, syn.rvecs, syn.tvecs, bows_m, strict=True):
        x, y = (2 * (o[:, :2] - o[:, :2].min(axis=0)) / np.ptp(o[:, :2], axis=0) - 1).T
        bent = np.column_stack([o[:, :2], wx * (1 - x**2) + wy * (1 - y**2)])
        px, _ = cv2.projectPoints(bent, r, t, K, D)
        obj.append(o)
        img.append(px.reshape(-1, 2) + rng.normal(0.0, 0.05, (len(o), 2)))
    return obj, img


@pytest.fixture(scope="module")
def bowed_session():
    return _bent(31, [(0.001, 0.0002)] * 16)


def test_the_gate_judges_the_reported_covariance(bowed_session) -> None:
    obj, img = bowed_session
    solution = solve_for_gate(obj, img, SIZE, "k1k2")
    cov = solution.covariance
    assert cov is not None and cov.inflated and cov.view_factor is not None
    gate = projection_gate(solution, SIZE, REGION, TIGHT_PX)
    jacobian = projection_uncertainty(
        solution.camera_matrix,
        solution.dist_coeffs,
        cov.jacobian_covariance,
        cov.names,
        solution.aspect_ratio,
        SIZE,
        (32, 24),
        rotation_fit=np.ones((24, 32), bool),
    )
    assert gate.value == pytest.approx(cov.view_factor * float(np.nanmax(jacobian.sigma_px)), rel=1e-6)
    assert f"view-level x {cov.view_factor:.2f}" in gate.message


def test_a_bowed_board_is_named_before_the_views(bowed_session) -> None:
    obj, img = bowed_session
    gate, named = _judged(obj, img, SIZE, "k1k2")
    assert named.reason == "projection.board_not_flat"
    assert named.hint is not None and named.hint.startswith("the board is not flat (it bows ")
    assert named.hint.endswith(f"then, if it is still uncertain: {gate.hint}")
    bow_mm = [float(w) for w in named.detail["board_bow_mm"]]
    assert 0.5 < bow_mm[0] < 1.5 and abs(bow_mm[1]) < 0.5  # the render's 1.0 and 0.2 mm
    assert named.value == gate.value


def test_a_board_that_flexes_from_view_to_view_is_named_before_the_views() -> None:
    rng = np.random.default_rng(32)
    obj, img = _bent(32, [tuple(rng.normal(0.0, 0.001, 2)) for _ in range(16)])
    gate, named = _judged(obj, img, SIZE, "k1k2")
    assert named.reason == "projection.views_scatter"
    assert named.hint is not None and named.hint.startswith("the board moved or flexed from view to view")
    assert named.hint.endswith(f"then, if it is still uncertain: {gate.hint}")
