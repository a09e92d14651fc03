"""The IMU as the board's metric gauge: a board registered at the wrong size, or a camera held with
another lens' intrinsics, is refused naming the cause; the right board and camera pass."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest

from calibctl.core.imu import gates
from calibctl.core.imu.calibrate import Calibration, calibrate
from calibctl.core.imu.metric import BoardScale, CameraFit
from calibctl.core.imu.samples import CameraFrames
from calibctl.core.imu.solve import SolveOptions
from calibctl.core.synth.imu import ImuCameraRecording
from tests.core.imu.conftest import as_inputs

QUICK = SolveOptions(folds=0)


def _solved(rec: ImuCameraRecording, frames: CameraFrames, square_mm: float) -> Calibration:
    imu, _, noise = as_inputs(rec)
    return calibrate(imu, frames, noise, QUICK, square_mm=square_mm)


def test_the_right_board_and_camera_pass(dance_calibration: Calibration) -> None:
    g = {x.gate: x for x in dance_calibration.gates}
    assert g["board_scale"].passed and g["camera_fit"].passed
    assert abs(g["board_scale"].value - 1.0) <= 3 * float(g["board_scale"].detail["sigma"])


def test_a_50_mm_board_registered_at_40_mm_is_refused_naming_its_size(dance: ImuCameraRecording) -> None:
    _, frames, _ = as_inputs(dance)
    small = replace(frames, object_points=tuple(0.8 * p for p in frames.object_points))
    cal = _solved(dance, small, square_mm=40.0)
    assert [g.gate for g in cal.failed] == ["board_scale"]
    gate = cal.failed[0]
    assert abs(gate.value - 1.25) <= 5 * float(gate.detail["sigma"]) + 0.01
    edge = re.search(r"its square or tag edge ([\d.]+) \+/- [\d.]+ mm, not 40\.0 mm", gate.message)
    assert edge is not None and abs(float(edge.group(1)) - 50.0) < 1.0, gate.message
    assert gate.hint is not None and "calibctl board add" in gate.hint


def test_another_lens_intrinsics_are_refused_naming_them(dance: ImuCameraRecording) -> None:
    _, frames, _ = as_inputs(dance)
    K = frames.camera_matrix.copy()
    K[0, 0] *= 0.94  # fx and fy 6 % short: the audit's 785 px held for an 835 px lens
    K[1, 1] *= 0.94
    cal = _solved(dance, replace(frames, camera_matrix=K), square_mm=50.0)
    failed = {g.gate: g for g in cal.failed}
    assert "camera_fit" in failed and "board_scale" not in failed
    assert failed["camera_fit"].message.startswith("the camera's intrinsics do not fit these images")


@pytest.mark.parametrize(
    ("scale", "sigma", "passed"),
    [
        (1.02, 0.002, True),  # within the few percent a print or an accelerometer's scale leaves
        (1.05, 0.002, False),  # off both the floor and 3 sigma
        (1.05, 0.02, True),  # a recording that cannot tell
        (0.95, 0.002, False),
    ],
)
def test_the_board_scale_gate_refuses_only_off_both_the_floor_and_three_sigma(scale, sigma, passed) -> None:
    gate = gates.board_scale(BoardScale(scale, sigma, 1.0))
    assert gate.passed is passed and "mm" not in gate.message
    assert (gate.hint is None) is passed


def test_a_camera_fit_is_refused_on_a_large_ratio_and_excess_or_when_it_cannot_be_computed() -> None:
    assert not gates.camera_fit(CameraFit(0.3, 0.3, 10, 12, float("nan"), float("nan"))).passed
    assert gates.camera_fit(CameraFit(0.3, 0.29, 1000, 60, 1.0, 0.0)).passed
    refused = gates.camera_fit(CameraFit(0.5, 0.3, 1000, 60, 5.0, 0.39))
    assert not refused.passed and refused.reason == "intrinsics_contradicted"
    # corners far more precise than the trajectory model: a large F on a misfit too small to matter
    assert gates.camera_fit(CameraFit(0.071, 0.029, 1000, 60, 194.0, 0.064)).passed
