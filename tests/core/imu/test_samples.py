"""IMU and camera input checks: units, stamp order, gaps, saturation."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.imu.gates import dropped_frames, imu_gaps, saturation
from calibctl.core.imu.plain import plain_calibration
from calibctl.core.imu.samples import (
    CameraFrames,
    ImuInputError,
    ImuNoise,
    ImuSamples,
    ImuUnitError,
    StampOrderError,
    check_rate_ratio,
    gaps,
)
from calibctl.core.synth.imu import ImuCameraRecording
from tests.core.imu.conftest import as_inputs


def test_a_gyro_in_deg_per_s_is_refused_naming_the_unit(dance: ImuCameraRecording) -> None:
    with pytest.raises(ImuUnitError, match=r"deg/s.*pi/180"):
        ImuSamples(dance.imu_t_s, np.degrees(dance.gyro_rad_s), dance.accel_m_s2)


def test_a_slow_gyro_in_deg_per_s_is_refused_against_the_camera_rate() -> None:
    with pytest.raises(ImuUnitError, match="deg/s"):
        check_rate_ratio(gyro_std_rad_s=0.3 * 57.3, camera_std_rad_s=0.3)
    check_rate_ratio(gyro_std_rad_s=0.3, camera_std_rad_s=0.31)


def test_an_accelerometer_in_g_is_refused_naming_the_unit(dance: ImuCameraRecording) -> None:
    with pytest.raises(ImuUnitError, match=r"reads g.*9\.80665"):
        ImuSamples(dance.imu_t_s, dance.gyro_rad_s, dance.accel_m_s2 / 9.80665)


def test_stamps_not_increasing_are_refused_where_they_go_wrong(dance: ImuCameraRecording) -> None:
    t = dance.imu_t_s.copy()
    t[100] = t[99]
    with pytest.raises(StampOrderError, match="not strictly increasing.*sample 100"):
        ImuSamples(t, dance.gyro_rad_s, dance.accel_m_s2)
    _, frames, _ = as_inputs(dance)
    stamps = frames.t_s.copy()
    stamps[[5, 6]] = stamps[[6, 5]]
    with pytest.raises(StampOrderError, match="camera"):
        CameraFrames(
            stamps,
            frames.object_points,
            frames.image_points,
            frames.camera_matrix,
            frames.dist_coeffs,
            frames.image_size,
        )


def test_noise_must_be_positive() -> None:
    with pytest.raises(ImuInputError, match="gyro_noise_density"):
        ImuNoise(0.0, 2e-3, 1e-5, 1e-4)


def test_gaps_and_dropped_frames_are_found_and_gated(dance: ImuCameraRecording) -> None:
    keep = np.ones(dance.imu_t_s.size, bool)
    keep[300:320] = False
    imu = ImuSamples(dance.imu_t_s[keep], dance.gyro_rad_s[keep], dance.accel_m_s2[keep])
    found = gaps(imu.t_s)
    assert found.shape == (1, 2) and found[0, 1] - found[0, 0] == pytest.approx(0.105)
    gate = imu_gaps(imu)
    assert not gate.passed and gate.value == pytest.approx(21.0) and gate.hint
    imu_ok, frames, _ = as_inputs(dance)
    assert imu_gaps(imu_ok).passed and dropped_frames(frames).passed
    sel = [f for f in range(len(frames.t_s)) if f % 5 != 2]
    thin = CameraFrames(
        frames.t_s[sel],
        tuple(frames.object_points[f] for f in sel),
        tuple(frames.image_points[f] for f in sel),
        frames.camera_matrix,
        frames.dist_coeffs,
        frames.image_size,
    )
    gate = dropped_frames(thin)
    assert not gate.passed and gate.detail["missing"] == 24


def test_clipped_samples_are_found(dance: ImuCameraRecording) -> None:
    gyro = dance.gyro_rad_s.copy()
    top = np.percentile(gyro[:, 0], 98)
    gyro[:, 0] = np.minimum(gyro[:, 0], top)
    imu = ImuSamples(dance.imu_t_s, gyro, dance.accel_m_s2)
    g, a = imu.saturated()
    pinned = gyro[:, 0] == top
    assert g.sum() >= 0.8 * pinned.sum() and not a.any()  # isolated touches of the top are not clipping
    assert not saturation(imu).passed
    ok = ImuSamples(dance.imu_t_s, dance.gyro_rad_s, dance.accel_m_s2, gyro_range_rad_s=8.7)
    assert saturation(ok).passed


def test_logs_that_do_not_overlap_are_refused_naming_the_clock(dance: ImuCameraRecording) -> None:
    imu, frames, noise = as_inputs(dance)
    late = ImuSamples(imu.t_s + 100.0, imu.gyro_rad_s, imu.accel_m_s2)
    with pytest.raises(ImuInputError, match="overlap for 0.000 s.*one clock"):
        plain_calibration(late, frames)
