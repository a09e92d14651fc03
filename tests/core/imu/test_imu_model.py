"""The IMU's own intrinsics (Kalibr's scale-misalignment model) as solve states: a rendered scale and
misalignment recovered within its sigma, an ideal IMU read as identity, a short recording refused."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.imu import intrinsics
from calibctl.core.imu.calibrate import Calibration, calibrate
from calibctl.core.imu.solve import SolveOptions, solve_imu_camera
from calibctl.core.synth.imu import ImuCameraRecording, synthesize_imu_camera
from tests.core.imu.conftest import as_inputs
from tests.core.imu.test_solve import z_scores

MODEL = SolveOptions(folds=0, jackknife_blocks=0, imu_model="scale-misalignment")
# Of the size a MEMS data sheet allows: scales and misalignments under 1 %, the gyro triad turned
# 0.3 deg from the accelerometer's, g-sensitivity 0.5e-3 (rad/s)/(m/s^2) at most.
X_TRUE = np.r_[
    [0.010, 0.004, -0.008, -0.003, 0.005, 0.006],
    [0.003, -0.004, 0.002],
    [-0.006, 0.003, 0.009, 0.002, -0.004, 0.005],
    1e-3 * np.array([0.5, -0.3, 0.2, 0.1, 0.4, -0.2, 0.3, 0.0, -0.5]),
]
SECONDS = 10.0  # a 3 s dance leaves the model's least-seen direction to its prior (the refusal below)


@pytest.fixture(scope="module")
def misaligned() -> ImuCameraRecording:
    return synthesize_imu_camera(5, duration_s=SECONDS, imu_scale_misalignment=intrinsics.matrices(X_TRUE))


@pytest.fixture(scope="module")
def misaligned_calibration(misaligned: ImuCameraRecording) -> Calibration:
    return calibrate(*as_inputs(misaligned), MODEL)


def test_the_model_recovers_a_rendered_scale_and_misalignment_within_its_sigma(
    misaligned: ImuCameraRecording, misaligned_calibration: Calibration
) -> None:
    s = misaligned_calibration.solution
    assert s is not None and s.converged and misaligned_calibration.passed
    m = s.imu_intrinsics
    assert m is not None and m.model == "scale-misalignment"
    assert np.all(np.abs((m.x - X_TRUE) / m.sigma) < 4.0)
    # The data, not the prior, pinned them: every sigma well inside its prior's.
    assert np.all(m.sigma < 0.3 * intrinsics.PRIOR_SIGMAS)
    assert np.all(np.abs(z_scores(s, misaligned.truth)) < 4.0)
    gate = next(g for g in misaligned_calibration.gates if g.gate == "imu_model_observability")
    assert gate.passed and gate.value >= intrinsics.MIN_INFORMATION
    assert s.state_names[-24:] == intrinsics.NAMES


def test_an_ideal_imu_reads_identity() -> None:
    rec = synthesize_imu_camera(5, duration_s=SECONDS)
    s = solve_imu_camera(*as_inputs(rec), MODEL)
    assert s.imu_intrinsics is not None
    assert np.all(np.abs(s.imu_intrinsics.x / s.imu_intrinsics.sigma) < 4.0)
    assert np.all(np.abs(z_scores(s, rec.truth)) < 4.0)


def test_the_calibrated_model_reports_no_imu_states_and_is_pulled_off_by_a_misaligned_imu(
    misaligned: ImuCameraRecording,
) -> None:
    s = solve_imu_camera(*as_inputs(misaligned), SolveOptions(folds=0, jackknife_blocks=0))
    assert s.imu_intrinsics is None
    assert not any(n in s.state_names for n in intrinsics.NAMES)
    # The unmodelled misalignment lands in the extrinsic rotation, far outside its sigma.
    assert np.max(np.abs(z_scores(s, misaligned.truth)[:3])) > 8.0


def test_a_short_recording_is_refused_naming_the_model() -> None:
    rec = synthesize_imu_camera(5, duration_s=3.0, imu_scale_misalignment=intrinsics.matrices(X_TRUE))
    cal = calibrate(*as_inputs(rec), MODEL)
    assert not cal.passed
    gate = next(g for g in cal.failed if g.gate == "imu_model_observability")
    assert gate.value < intrinsics.MIN_INFORMATION
    assert "scale-misalignment" in gate.message and "--imu-model calibrated" in (gate.hint or "")


def test_an_identity_model_renders_the_ideal_imu() -> None:
    ideal = synthesize_imu_camera(6, duration_s=1.0)
    same = synthesize_imu_camera(6, duration_s=1.0, imu_scale_misalignment=intrinsics.matrices(np.zeros(24)))
    assert np.allclose(same.gyro_rad_s, ideal.gyro_rad_s, rtol=0, atol=1e-12)
    assert np.allclose(same.accel_m_s2, ideal.accel_m_s2, rtol=0, atol=1e-12)


def test_an_unknown_imu_model_is_refused(misaligned: ImuCameraRecording) -> None:
    with pytest.raises(ValueError, match="scale-misalignment"):
        solve_imu_camera(*as_inputs(misaligned), SolveOptions(imu_model="scale"))
