"""The biases as random walks (``SolveOptions.bias_walk``): a bias that wanders is followed through the
recording, the extrinsic stays within its sigma, and the constant model is what it was."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calibctl.core.imu.samples import ImuSamples
from calibctl.core.imu.solve import SolveOptions, solve_imu_camera
from calibctl.core.synth.imu import ImuCameraRecording
from tests.core.imu.conftest import as_inputs
from tests.core.imu.test_solve import z_scores

OPTIONS = SolveOptions(folds=0, jackknife_blocks=0)
ACCEL_WALK = 0.02  # m/s^3/sqrt(Hz): the accelerometer bias wanders about 0.05 m/s^2 over the render


@pytest.fixture(scope="module")
def wandering(dance: ImuCameraRecording) -> tuple[ImuSamples, np.ndarray]:
    """The dance's IMU with a random walk of ACCEL_WALK added to the accelerometer bias, and the walk."""
    rng = np.random.default_rng(7)
    t = dance.imu_t_s
    steps = ACCEL_WALK * np.sqrt(np.diff(t, prepend=t[0]))[:, None] * rng.standard_normal((t.size, 3))
    walk = np.cumsum(steps, axis=0)
    return ImuSamples(t, dance.gyro_rad_s, dance.accel_m_s2 + walk), walk


def test_a_wandering_bias_is_followed_and_the_extrinsic_stays_within_its_sigma(
    dance: ImuCameraRecording, wandering: tuple[ImuSamples, np.ndarray]
) -> None:
    imu, walk = wandering
    _, frames, noise = as_inputs(dance)
    noise = replace(noise, accel_random_walk=ACCEL_WALK)
    walked = solve_imu_camera(imu, frames, noise, replace(OPTIONS, bias_walk=True))
    constant = solve_imu_camera(imu, frames, noise, OPTIONS)
    truth = dance.truth.accel_bias_m_s2 + walk[np.searchsorted(imu.t_s, walked.residuals["imu_t_s"])]
    # The walk's estimate follows the bias's wandering (its level is pinned only as well as the constant
    # model pins it, hence both sides about their means); the constant model can only give its mean.
    error = walked.residuals["accel_bias_m_s2"] - truth
    assert np.linalg.norm(np.std(error, axis=0)) < 0.5 * np.linalg.norm(np.std(truth, axis=0))
    assert np.ptp(constant.residuals["accel_bias_m_s2"], axis=0).max() == 0.0
    assert walked.accel_rms_m_s2 < constant.accel_rms_m_s2
    assert np.all(np.abs(z_scores(walked, dance.truth)) < 4.0)


def test_on_a_constant_bias_the_walk_finds_the_constant(dance: ImuCameraRecording) -> None:
    s = solve_imu_camera(*as_inputs(dance), replace(OPTIONS, bias_walk=True))
    assert "ba_x" not in s.state_names and "bg_x" not in s.state_names  # the walk's controls carry them
    assert np.allclose(s.gyro_bias_rad_s, dance.truth.gyro_bias_rad_s, atol=1e-3)
    assert np.allclose(s.accel_bias_m_s2, dance.truth.accel_bias_m_s2, atol=0.03)
    assert np.all(np.abs(z_scores(s, dance.truth)) < 4.0)


def test_the_walk_and_a_linear_drift_are_one_or_the_other(dance: ImuCameraRecording) -> None:
    with pytest.raises(ValueError, match="bias_walk and bias_drift"):
        solve_imu_camera(*as_inputs(dance), replace(OPTIONS, bias_walk=True, bias_drift=True))


def test_fix_imu_sigma_keeps_the_noise_files_densities(dance: ImuCameraRecording) -> None:
    # The render's IMU noise is its noise file's, so the raise would be near 1 anyway; a noise file that
    # claims a tenth of it is raised back by the default and kept by fix_imu_sigma (Kalibr's weighting).
    imu, frames, noise = as_inputs(dance)
    quiet = replace(noise, gyro_noise_density=noise.gyro_noise_density / 10)
    raised = solve_imu_camera(imu, frames, quiet, OPTIONS)
    fixed = solve_imu_camera(imu, frames, quiet, replace(OPTIONS, fix_imu_sigma=True))
    assert raised.imu_variance_factors[0] > 5.0
    assert fixed.imu_variance_factors == (1.0, 1.0)
    # Ten times too confident in the gyro: the gyro bias's sigma shrinks with it (the corners pin the
    # trajectory's rotation too, so by less than ten times).
    k = fixed.state_names.index("bg_x")
    assert np.sqrt(fixed.covariance[k, k]) < 0.95 * np.sqrt(raised.covariance[k, k])
