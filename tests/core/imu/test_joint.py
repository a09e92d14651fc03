"""Two cameras and one IMU in one solve: each camera's T_imu_cam and td against one IMU trajectory,
gravity and biases; the truth within the sigma, and the shared IMU states tighten every camera's sigma."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calibctl.core.imu import gates
from calibctl.core.imu.calibrate import calibrate_cameras
from calibctl.core.imu.plain import board_track
from calibctl.core.imu.samples import ImuInputError
from calibctl.core.imu.solve import ImuCameraSolution, SolveOptions, solve_imu_camera, solve_imu_cameras
from calibctl.core.synth.imu import (
    EUROC_LIKE_T_CAM0_CAM1,
    EUROC_LIKE_T_IMU_CAM,
    ImuCameraRecording,
    synthesize_imu_camera,
)
from tests.core.imu.conftest import as_inputs, more_frames
from tests.core.imu.test_solve import z_scores

OPTIONS = SolveOptions(folds=0, jackknife_blocks=0)


@pytest.fixture(scope="module")
def stereo() -> ImuCameraRecording:
    return synthesize_imu_camera(
        4, duration_s=3.0, more_cameras=(EUROC_LIKE_T_IMU_CAM @ EUROC_LIKE_T_CAM0_CAM1,)
    )


@pytest.fixture(scope="module")
def joint(stereo: ImuCameraRecording) -> list[ImuCameraSolution]:
    imu, frames, noise = as_inputs(stereo)
    return solve_imu_cameras(imu, [frames, more_frames(stereo, 0)], noise, OPTIONS)


def test_a_second_camera_leaves_the_first_camera_and_the_imu_as_rendered(stereo: ImuCameraRecording) -> None:
    alone = synthesize_imu_camera(4, duration_s=3.0)
    assert np.array_equal(alone.gyro_rad_s, stereo.gyro_rad_s)
    assert all(np.array_equal(a, b) for a, b in zip(alone.image_points, stereo.image_points, strict=True))
    assert not np.array_equal(stereo.more_cameras[0].image_points[0], stereo.image_points[0])


def test_the_joint_solve_recovers_both_cameras_within_their_sigma(
    stereo: ImuCameraRecording, joint: list[ImuCameraSolution]
) -> None:
    assert len(joint) == 2 and all(s.converged for s in joint)
    truths = (stereo.truth, replace(stereo.truth, T_imu_cam=stereo.more_cameras[0].T_imu_cam))
    for s, truth in zip(joint, truths, strict=True):
        assert np.all(np.abs(z_scores(s, truth)) < 4.0)
        assert s.state_names[:7] == ("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "td")
    # One IMU: the biases and gravity are the same states for both cameras.
    assert np.array_equal(joint[0].gyro_bias_rad_s, joint[1].gyro_bias_rad_s)
    assert np.array_equal(joint[0].residuals["gyro_rad_s"], joint[1].residuals["gyro_rad_s"])


def test_sharing_the_imu_states_tightens_each_cameras_sigma(
    stereo: ImuCameraRecording, joint: list[ImuCameraSolution]
) -> None:
    imu, frames, noise = as_inputs(stereo)
    for s, f in zip(joint, (frames, more_frames(stereo, 0)), strict=True):
        alone = solve_imu_camera(imu, f, noise, OPTIONS)
        # The other camera's corners pin the trajectory this camera's extrinsic is measured against.
        assert np.all(s.sigma_rotation_deg < 0.9 * alone.sigma_rotation_deg)
        assert np.all(s.sigma_translation_mm < alone.sigma_translation_mm)
        assert s.sigma_td_ms < alone.sigma_td_ms


def test_joint_calibration_gates_each_camera(stereo: ImuCameraRecording) -> None:
    imu, frames, noise = as_inputs(stereo)
    cals = calibrate_cameras(imu, [frames, more_frames(stereo, 0)], noise, OPTIONS)
    assert len(cals) == 2
    for cal in cals:
        assert cal.passed, [g.message for g in cal.failed]
        assert {"rotational_excitation", "td_sigma", "dropped_frames"} <= {g.gate for g in cal.gates}


def test_no_camera_is_refused() -> None:
    rec = synthesize_imu_camera(4, duration_s=1.0)
    imu, _, noise = as_inputs(rec)
    with pytest.raises(ImuInputError, match="at least one camera"):
        solve_imu_cameras(imu, [], noise, OPTIONS)


def test_a_camera_the_rig_relates_is_held_through_its_rig_pose(
    stereo: ImuCameraRecording, joint: list[ImuCameraSolution]
) -> None:
    imu, frames, noise = as_inputs(stereo)
    tied = solve_imu_cameras(
        imu, [frames, more_frames(stereo, 0)], noise, OPTIONS, rig=[None, EUROC_LIKE_T_CAM0_CAM1]
    )
    assert np.allclose(tied[1].T_imu_cam, tied[0].T_imu_cam @ EUROC_LIKE_T_CAM0_CAM1)
    truths = (stereo.truth, replace(stereo.truth, T_imu_cam=stereo.more_cameras[0].T_imu_cam))
    for s, truth in zip(tied, truths, strict=True):
        assert np.all(np.abs(z_scores(s, truth)) < 4.0)
    # Six fewer states for the same corners: the first camera's rotation is pinned at least as well.
    assert np.all(tied[0].sigma_rotation_deg <= joint[0].sigma_rotation_deg)
    assert np.array_equal(tied[0].sigma_rotation_deg, tied[1].sigma_rotation_deg)


def test_a_rig_pose_the_corners_contradict_fails_the_rig_pose_gate(stereo: ImuCameraRecording) -> None:
    imu, frames, noise = as_inputs(stereo)
    cameras = [frames, more_frames(stereo, 0)]
    good = calibrate_cameras(imu, cameras, noise, OPTIONS, rig=[None, EUROC_LIKE_T_CAM0_CAM1])
    (gate,) = [g for g in good[1].gates if g.gate == "rig_pose"]
    assert gate.passed and gate.value < 1.5
    assert "rig_pose_camera_1" in {g.gate for g in good[0].gates if g.passed}
    moved = EUROC_LIKE_T_CAM0_CAM1.copy()
    moved[0, 3] += 0.03  # the rig says 14 cm, the cameras are 11 cm apart
    bad = calibrate_cameras(imu, cameras, noise, OPTIONS, rig=[None, moved])
    (gate,) = [g for g in bad[1].gates if g.gate == "rig_pose"]
    assert not gate.passed and gate.reason == "rig_pose_contradicted"
    assert gate.hint is not None and "re-solve the rig" in gate.hint
    # The held camera's corners moved the first camera's extrinsic: its verdict fails with them.
    assert not bad[0].passed and "rig_pose_camera_1" in {g.gate for g in bad[0].failed}


def test_the_rig_pose_gate_judges_the_held_solution_that_is_reported(
    stereo: ImuCameraRecording, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Motion that cannot pin td, as the td-sigma gate would say it: every free solve fails it, so the
    # cameras are solved again with td held (here 2 ms off the truth, so the two solves' corners differ).
    free_gate = gates.td_sigma

    def unpinned(sigma_td_ms: float, held: bool):
        return free_gate(sigma_td_ms if held else 10.0, held)

    monkeypatch.setattr(gates, "td_sigma", unpinned)
    imu, frames, noise = as_inputs(stereo)
    cameras = [frames, more_frames(stereo, 0)]
    rig = [None, EUROC_LIKE_T_CAM0_CAM1]
    free = solve_imu_cameras(imu, cameras, noise, OPTIONS, rig=rig)
    cal = calibrate_cameras(imu, cameras, noise, OPTIONS, fallback_td_s=stereo.truth.td_s + 2e-3, rig=rig)
    assert cal[1].held == "td" and cal[1].solution is not None
    pnp = gates.pnp_rms_px(cameras[1], board_track(cameras[1]))
    (gate,) = [g for g in cal[1].gates if g.gate == "rig_pose"]
    assert gate.value == pytest.approx(cal[1].solution.corner_rms_px / pnp)
    assert abs(gate.value - free[1].corner_rms_px / pnp) > 0.01
    (copy,) = [g for g in cal[0].gates if g.gate == "rig_pose_camera_1"]
    assert copy.value == gate.value
