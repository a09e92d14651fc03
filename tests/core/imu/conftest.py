"""Shared camera + IMU renders (session-scoped: each rendered and solved once)."""

from __future__ import annotations

import pytest

from calibctl.core.imu.calibrate import Calibration, calibrate
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples
from calibctl.core.imu.solve import SolveOptions
from calibctl.core.synth.imu import ImuCameraRecording, synthesize_imu_camera


def as_inputs(rec: ImuCameraRecording) -> tuple[ImuSamples, CameraFrames, ImuNoise]:
    imu = ImuSamples(rec.imu_t_s, rec.gyro_rad_s, rec.accel_m_s2)
    frames = CameraFrames(
        rec.cam_t_s, rec.object_points, rec.image_points, rec.camera_matrix, rec.dist_coeffs, rec.image_size
    )
    noise = ImuNoise(rec.truth.gyro_noise_density, rec.truth.accel_noise_density, 1e-5, 1e-4)
    return imu, frames, noise


@pytest.fixture(scope="session")
def dance() -> ImuCameraRecording:
    return synthesize_imu_camera(1, motion="dance", duration_s=6.0)


@pytest.fixture(scope="session")
def dance_calibration(dance: ImuCameraRecording) -> Calibration:
    return calibrate(*as_inputs(dance), SolveOptions(folds=3))


@pytest.fixture(scope="session")
def corridor() -> ImuCameraRecording:
    return synthesize_imu_camera(1, motion="corridor", duration_s=6.0)


@pytest.fixture(scope="session")
def rolling() -> ImuCameraRecording:
    """A 3 s rolling-shutter dance: 30 us per row."""
    return synthesize_imu_camera(2, motion="dance", duration_s=3.0, line_delay_s=30e-6)
