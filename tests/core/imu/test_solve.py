"""The joint camera-IMU estimator on renders: truth within its sigma, honest residuals, td moves with
the stamps, the rolling-shutter line delay."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.extrinsics import se3
from calibctl.core.imu.calibrate import Calibration
from calibctl.core.imu.samples import ImuSamples
from calibctl.core.imu.solve import SolveOptions, solve_imu_camera
from calibctl.core.synth.imu import ImuCameraRecording, synthesize_imu_camera
from tests.core.imu.conftest import as_inputs


def z_scores(solution, truth) -> np.ndarray:
    """(7,) errors over sigmas: rotation (left, IMU frame) 3, translation 3, td."""
    d_rot = se3.rotvec_from_rotation(solution.T_imu_cam[:3, :3] @ truth.T_imu_cam[:3, :3].T)
    d_t = solution.T_imu_cam[:3, 3] - truth.T_imu_cam[:3, 3]
    err = np.r_[d_rot, d_t, solution.td_s - truth.td_s]
    return err / np.sqrt(np.diag(solution.covariance_7))


def test_recovers_the_truth_within_its_sigma(
    dance: ImuCameraRecording, dance_calibration: Calibration
) -> None:
    s = dance_calibration.solution
    assert s is not None and s.converged
    assert np.all(np.abs(z_scores(s, dance.truth)) < 4.0)
    # Small, but not suspiciously small: the render's noise gives tenths of a mm and hundredths of a deg.
    assert np.all(s.sigma_rotation_deg < 0.1) and np.all(s.sigma_translation_mm < 2.0)
    assert 0.0 < s.td_crlb_ms <= s.sigma_td_ms < 0.5


def test_biases_gravity_and_residuals_match_the_render(
    dance: ImuCameraRecording, dance_calibration: Calibration
) -> None:
    s = dance_calibration.solution
    assert s is not None
    assert np.allclose(s.gyro_bias_rad_s, dance.truth.gyro_bias_rad_s, atol=1e-3)
    assert np.allclose(s.accel_bias_m_s2, dance.truth.accel_bias_m_s2, atol=0.03)
    assert np.degrees(np.arccos(s.gravity_w_m_s2 @ dance.truth.gravity_w_m_s2 / 9.80665**2)) < 0.5
    # Per-coordinate corner sigma recovered from the residuals; RMS is over both coordinates.
    assert s.corner_sigma_px == pytest.approx(dance.truth.noise_px, rel=0.1)
    assert s.gyro_rms_rad_s == pytest.approx(np.sqrt(3 * 200) * dance.truth.gyro_noise_density, rel=0.15)
    assert s.timeshift_cam_imu_s == s.td_s
    assert np.allclose(s.T_cam_imu @ s.T_imu_cam, np.eye(4))


def test_k_fold_held_out_residuals_stay_near_the_fit(dance_calibration: Calibration) -> None:
    s = dance_calibration.solution
    assert s is not None and s.held_out is not None
    assert len(s.held_out.corner_rms_px) == 3
    assert max(s.held_out.corner_rms_px) < 1.3 * s.corner_rms_px
    assert max(s.held_out.gyro_rms_rad_s) < 1.3 * s.gyro_rms_rad_s
    assert max(s.held_out.accel_rms_m_s2) < 1.3 * s.accel_rms_m_s2


def test_shifting_the_imu_stamps_moves_td_by_the_shift(
    dance: ImuCameraRecording, dance_calibration: Calibration
) -> None:
    imu, frames, noise = as_inputs(dance)
    shifted = ImuSamples(imu.t_s + 0.005, imu.gyro_rad_s, imu.accel_m_s2)
    s = solve_imu_camera(shifted, frames, noise, SolveOptions(folds=0, jackknife_blocks=0))
    base = dance_calibration.solution
    assert base is not None
    assert s.td_s - base.td_s == pytest.approx(0.005, abs=2e-4)


@pytest.mark.parametrize("line_delay_us", [30.0, 0.0])
def test_line_delay_is_recovered_with_its_sigma(line_delay_us: float) -> None:
    # 0: a global-shutter render reads ~0 within the sigma (the state does not invent a ramp).
    rec = synthesize_imu_camera(2, motion="dance", duration_s=4.0, line_delay_s=line_delay_us * 1e-6)
    s = solve_imu_camera(*as_inputs(rec), SolveOptions(folds=0, jackknife_blocks=0, estimate_line_delay=True))
    assert s.line_delay_s is not None and s.sigma_line_delay_us is not None
    assert abs(s.line_delay_s * 1e6 - line_delay_us) < 4 * s.sigma_line_delay_us
    assert s.sigma_line_delay_us < 3.0
    assert np.all(np.abs(z_scores(s, rec.truth)) < 4.0)
