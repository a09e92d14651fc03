"""core.compare.projection_diff on seeded corner-level sessions: unchanged cameras are "same", a 0.3 % focal
change or a 1 px principal-point shift is "different"; the plumbing (Jacobians, scale, models) is exact."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from calibctl.core.compare.lens import FISHEYE_PARAMETERS, Lens, project, unproject
from calibctl.core.compare.projection_diff import ALPHA, projection_diff
from tests.core.compare.sessions import SIZE, lens, solve, true_K

SEEDS_FAST = (0, 1)


@pytest.fixture(scope="module")
def reference() -> list[Lens]:
    return [lens(true_K(), 100 + s) for s in SEEDS_FAST]


@pytest.mark.parametrize("seed", SEEDS_FAST)
def test_an_unchanged_camera_recalibrated_is_the_same(reference: list[Lens], seed: int) -> None:
    result = projection_diff(reference[seed], lens(true_K(), 200 + seed))
    assert result.significant is False, result.reasons
    assert result.raw.test is not None and result.raw.test.dof == 5  # fy cx cy k1 k2 of one model
    assert result.raw.test.p_value > ALPHA / 2
    assert result.raw.percentiles_px["max"] > 0.0  # two noisy solves never agree exactly


@pytest.mark.parametrize("seed", SEEDS_FAST)
def test_a_focal_change_of_0_3_percent_is_different(reference: list[Lens], seed: int) -> None:
    result = projection_diff(reference[seed], lens(true_K(focal_scale=1.003), 300 + seed))
    assert result.significant is True
    assert result.raw.test is not None and result.raw.test.p_value < 1e-6
    assert "as stored" in result.reasons[0]


@pytest.mark.parametrize("seed", SEEDS_FAST)
def test_a_1px_principal_point_shift_is_different_and_mostly_a_rotation(
    reference: list[Lens], seed: int
) -> None:
    result = projection_diff(reference[seed], lens(true_K(dcx_px=1.0), 400 + seed))
    assert result.significant is True
    # a shift of the principal point is nearly a yaw of the camera frame: the fitted rotation takes most of it
    assert result.fit.percentiles_px["p50"] < 0.5 * result.raw.percentiles_px["p50"]
    assert 0.03 < result.rotation_fit_deg < 0.12  # atan(1 px / 800 px) = 0.072 deg, plus the solves' noise


def test_the_same_lens_is_identical_and_the_test_has_no_false_flag(reference: list[Lens]) -> None:
    result = projection_diff(reference[0], reference[0])
    assert result.raw.percentiles_px["max"] < 1e-9 and result.fit.percentiles_px["max"] < 1e-9
    assert result.significant is False and result.raw.test is not None and result.raw.test.statistic < 1e-12


def test_expected_spread_grows_toward_the_corners(reference: list[Lens]) -> None:
    result = projection_diff(reference[0], reference[1])
    sigma = result.raw.sigma_px
    assert sigma is not None
    centre = np.argmin(np.linalg.norm(result.pixels_px - np.array([319.5, 239.5]), axis=1))
    corner = np.argmin(np.linalg.norm(result.pixels_px, axis=1))
    assert sigma[corner] > sigma[centre] > 0


def test_a_rescaled_readout_compares_as_identical_after_the_scale(reference: list[Lens]) -> None:
    half = reference[0].scaled(0.5)
    assert half.image_size == (320, 240)
    with pytest.raises(ValueError, match="image sizes differ"):
        projection_diff(reference[0], half)
    back = projection_diff(reference[0], half.scaled(2.0))
    assert back.raw.percentiles_px["max"] < 1e-9 and back.significant is False


def test_without_a_covariance_there_are_numbers_and_no_verdict(reference: list[Lens]) -> None:
    bare = dataclasses.replace(reference[1], covariance=None, parameters=())
    result = projection_diff(reference[0], bare)
    assert result.significant is None and "no covariance" in result.reasons[0]
    assert result.raw.percentiles_px["max"] > 0 and result.raw.test is None


def test_different_lens_models_are_compared_by_projection() -> None:
    # k1k2 and k1k2k3 solved on the same corners: two parameter vectors that cannot be compared one by one
    a, b = solve(true_K(), 7), solve(true_K(), 7, model="k1k2k3")
    from calibctl.core.compare.lens import lens_from_solution

    result = projection_diff(lens_from_solution(a), lens_from_solution(b))
    assert result.raw.test is not None and result.raw.test.dof > 5  # both models' directions are tested
    assert result.significant is False, result.reasons  # the same corners: no difference beyond noise


def test_projection_jacobians_match_finite_differences() -> None:
    K = np.array([[420.0, 0.0, 330.0], [0.0, 415.0, 242.0], [0.0, 0.0, 1.0]])
    D = np.array([0.02, -0.01, 0.004, -0.001])
    fisheye = Lens(K, D, SIZE, True, np.eye(8), FISHEYE_PARAMETERS)
    pinhole = Lens(
        K,
        np.array([-0.2, 0.08, 0.0, 0.0, 0.0]),
        SIZE,
        False,
        np.eye(5),
        ("fy", "cx", "cy", "k1", "k2"),
        aspect=420.0 / 415.0,
    )
    rays, ok = unproject(fisheye, np.array([[100.0, 80.0], [330.0, 240.0], [600.0, 400.0]]))
    assert ok.all()
    for lens_ in (fisheye, pinhole):
        p = project(lens_, rays, (0.01, -0.02, 0.03))
        assert p.J_theta is not None
        h = 1e-6
        for k, name in enumerate(lens_.parameters):
            bumped = _bump(lens_, name, h)
            numeric = (project(bumped, rays, (0.01, -0.02, 0.03)).q_px - p.q_px) / h
            np.testing.assert_allclose(p.J_theta[:, :, k], numeric, rtol=1e-4, atol=1e-3)
        R, _ = cv2.Rodrigues(np.array([0.01, -0.02, 0.03]))
        for k in range(3):
            step = np.zeros(3)
            step[k] = h
            numeric = (project(lens_, rays + step, (0.01, -0.02, 0.03)).q_px - p.q_px) / h
            np.testing.assert_allclose(p.J_point[:, :, k], numeric, rtol=1e-4, atol=1e-2)


def _bump(lens_: Lens, name: str, h: float) -> Lens:
    K, D = lens_.camera_matrix.copy(), lens_.dist_coeffs.copy()
    index = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}
    if name in index:
        K[index[name]] += h
        if name == "fy" and lens_.aspect is not None:
            K[0, 0] += lens_.aspect * h
    else:
        D[
            ["k1", "k2", "p1", "p2", "k3", "k4"].index(name)
            if not lens_.fisheye
            else ["k1", "k2", "k3", "k4"].index(name)
        ] += h
    return dataclasses.replace(lens_, camera_matrix=K, dist_coeffs=D)


def test_samples_past_a_lens_polynomial_fold_over_are_never_compared() -> None:
    # x (1 + k1 r^2) with k1 = -0.5 peaks at r = 0.816: beyond it B's polynomial folds back, so the wide
    # pinhole A's corner rays have no honest projection through B
    K = np.array([[300.0, 0.0, 319.5], [0.0, 300.0, 239.5], [0.0, 0.0, 1.0]])
    a = Lens(K, np.zeros(5), SIZE)
    b = Lens(K, np.array([-0.5, 0.0, 0.0, 0.0, 0.0]), SIZE)
    result = projection_diff(a, b, grid=(16, 12))
    assert 0 < result.dropped < 16 * 12
    radius = np.linalg.norm((result.pixels_px - K[:2, 2]) / 300.0, axis=1)
    assert radius.max() < 1.0 and result.significant is None
