"""core.compare on fisheye lenses (cv2.fisheye's projection and Jacobians): one 150 deg lens solved twice is
the same, its focal length 0.3 % longer is different, and pixels beyond the image circle's rays are never
compared."""

from __future__ import annotations

import pytest

from calibctl.core.compare.lens import FISHEYE_MAX_DEG, lens_from_solution
from calibctl.core.compare.projection_diff import projection_diff
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

SIZE = (640, 480)


def _lens(camera: FisheyeCamera, seed: int):
    s = synthesize_fisheye_session(camera, 24, seed, noise_px=0.03)
    return lens_from_solution(
        solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "fisheye")
    )


@pytest.fixture(scope="module")
def camera() -> FisheyeCamera:
    return FisheyeCamera.from_fov(SIZE, 150.0, circular=True)


def test_a_fisheye_solved_twice_is_the_same_and_a_longer_focal_is_not(camera: FisheyeCamera) -> None:
    a = _lens(camera, 1)
    assert a.fisheye and a.parameters == ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")
    same = projection_diff(a, _lens(camera, 2))
    assert same.significant is False, same.reasons
    assert same.raw.test is not None and same.raw.test.dof == 8
    K = camera.K.copy()
    K[:2, :2] *= 1.003
    longer = FisheyeCamera(K, camera.dist, camera.image_size, camera.fov_deg, camera.circle_radius_px)
    assert projection_diff(a, _lens(longer, 3)).significant is True


def test_rays_past_the_fisheye_limit_are_dropped(camera: FisheyeCamera) -> None:
    wide = FisheyeCamera.from_fov(SIZE, 200.0, circular=False)
    a = _lens(camera, 1)
    b = type(a)(wide.K, wide.dist, SIZE, True, a.covariance, a.parameters, None, "fisheye")
    result = projection_diff(b, b)
    assert result.dropped > 0  # a 200 deg full-frame lens sees past FISHEYE_MAX_DEG in its corners
    assert FISHEYE_MAX_DEG < 90.0 and result.raw.percentiles_px["max"] < 1e-9
