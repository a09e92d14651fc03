"""The changed-camera test on seeded corners (0.2 px iid noise): the scan finds the view the camera changed at
and the step's size, the judge calls it; one camera throughout is not called changed."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.intrinsics.camera_change import judge_change, scan_change
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.corners import synthesize_session

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
D = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])
SIZE = (640, 480)


def _session(seed: int, K_after: np.ndarray, n_before: int = 12, n_after: int = 12, noise_px: float = 0.2):
    a = synthesize_session(K, D, SIZE, n_before, seed, noise_px=noise_px)
    b = synthesize_session(K_after, D, SIZE, n_after, seed + 1000, noise_px=noise_px)
    obj = list(a.object_points_per_view) + list(b.object_points_per_view)
    img = list(a.image_points_per_view) + list(b.image_points_per_view)
    return obj, img


def _after(focal: float = 0.0, dcx: float = 0.0) -> np.ndarray:
    K2 = K.copy()
    K2[0, 0] *= 1 + focal
    K2[1, 1] *= 1 + focal
    K2[0, 2] += dcx
    return K2


@pytest.mark.parametrize("seed", [3, 4])
def test_a_one_percent_focal_step_is_found_where_it_happened_and_called(seed: int) -> None:
    obj, img = _session(seed, _after(focal=0.01))
    sol = solve_intrinsics(obj, img, SIZE, "k1k2")
    assert sol.covariance is not None
    scan = scan_change(sol.covariance)
    assert scan is not None and abs(scan.split - 12) <= 2  # at 0.2 px a view or two either side
    step = dict(zip(scan.names, scan.step, strict=True))  # k1k2 ties fx to fy: the focal length is fy
    assert step["fy"] == pytest.approx(8.0, rel=0.3)
    verdict = judge_change(sol, obj, img, SIZE)
    assert verdict is not None and verdict.changed and verdict.split == scan.split
    assert verdict.focal_step == pytest.approx(0.01, abs=0.002) and verdict.chi2 > verdict.limit


def test_a_three_pixel_principal_point_step_is_called() -> None:
    obj, img = _session(5, _after(dcx=3.0), noise_px=0.05)  # the detector's noise on renders, not 0.2 px
    verdict = judge_change(solve_intrinsics(obj, img, SIZE, "k1k2"), obj, img, SIZE)
    assert verdict is not None and verdict.changed
    assert verdict.centre_step_px == pytest.approx(3.0, abs=1.0) and abs(verdict.focal_step) < 0.003


@pytest.mark.parametrize("seed", [6, 7, 8])
def test_one_camera_throughout_is_not_called_changed(seed: int) -> None:
    obj, img = _session(seed, K)
    verdict = judge_change(solve_intrinsics(obj, img, SIZE, "k1k2"), obj, img, SIZE)
    assert verdict is not None and not verdict.changed and verdict.chi2 < verdict.limit


def test_too_few_views_to_split_is_no_verdict() -> None:
    obj, img = _session(9, _after(focal=0.01), 4, 5)
    sol = solve_intrinsics(obj, img, SIZE, "k1k2")
    assert sol.covariance is not None and scan_change(sol.covariance) is None
    assert judge_change(sol, obj, img, SIZE) is None
