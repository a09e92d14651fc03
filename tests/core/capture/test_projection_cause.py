"""The projection gate names the cause first: when a camera that changed during the session, or a lens model
that cannot describe a wide lens, explains the uncertainty, that cause and its fix come before the views'
hint (seeded corners; a tight threshold makes every gate here fail, so only the named cause differs)."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.capture.projection_gate import Region, cause_first, projection_gate, solve_for_gate
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
