"""The row test: a time offset is constant across image rows, a rolling shutter ramps with the row; and
the report's series: the gyro meets the camera's board-derived rate once td is applied."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calibctl.core.imu.calibrate import Calibration
from calibctl.core.imu.rows import report_series, row_test
from calibctl.core.imu.solve import SolveOptions, solve_imu_camera
from calibctl.core.synth.imu import ImuCameraRecording
from tests.core.imu.conftest import as_inputs

FAST = SolveOptions(folds=0, jackknife_blocks=0)


def test_a_global_shutter_leaves_no_row_ramp(dance: ImuCameraRecording, dance_calibration: Calibration):
    _, frames, _ = as_inputs(dance)
    test = row_test(dance_calibration.solution, frames)
    assert test is not None and not test.significant
    assert "constant across rows" in test.message and "--line-delay" not in test.message
    assert test.corners > 1000 and np.all(test.counts > 0)


def test_a_rolling_shutter_solved_without_line_delay_is_named(rolling: ImuCameraRecording) -> None:
    imu, frames, noise = as_inputs(rolling)
    test = row_test(solve_imu_camera(imu, frames, noise, FAST), frames)
    assert test is not None and test.significant and test.slope_s_per_row > 0
    assert test.message.startswith("rolling shutter suspected: solve with --line-delay")


def test_with_the_line_delay_solved_the_rows_no_longer_ramp(rolling: ImuCameraRecording) -> None:
    imu, frames, noise = as_inputs(rolling)
    solution = solve_imu_camera(imu, frames, noise, replace(FAST, estimate_line_delay=True))
    test = row_test(solution, frames)
    assert test is not None and test.line_delay_solved and not test.significant


def test_residuals_of_other_frames_are_not_matched(dance: ImuCameraRecording, dance_calibration) -> None:
    _, frames, _ = as_inputs(dance)
    fewer = replace(
        frames,
        t_s=frames.t_s[1:],
        object_points=frames.object_points[1:],
        image_points=frames.image_points[1:],
    )
    assert row_test(dance_calibration.solution, fewer) is None


def test_the_camera_rate_meets_the_gyro_once_td_is_applied(dance, dance_calibration) -> None:
    imu, frames, _ = as_inputs(dance)
    solution = dance_calibration.solution

    def misfit(td_s: float) -> float:
        s = report_series(replace(solution, td_s=td_s), imu, frames)
        ok = np.all(np.isfinite(s.camera_rate_rad_s), axis=1)
        return float(np.sqrt(np.mean((s.gyro_rad_s[ok] - s.camera_rate_rad_s[ok]) ** 2)))

    series = report_series(solution, imu, frames)
    assert series.t_s.size == series.corner_rms_px.size == series.gyro_rad_s.shape[0]
    assert misfit(solution.td_s) < 0.5 * misfit(solution.td_s + 0.04)
    assert misfit(solution.td_s) < 0.5 * misfit(solution.td_s - 0.04)
