"""Robot-arm hand-eye with a fisheye camera: the board poses go through the calibration's own lens model.

A 150 deg equidistant lens on a gripper, 15 rendered arm poses, the true K and k1..k4 stored as the
camera's active ``fisheye`` calibration. Through the fisheye model X is within 3 sigma of the truth
(0.008-0.023 mm off, sigma 0.005-0.009 mm). Read as a pinhole (solvePnP takes k1..k4 for k1 k2 p1 p2), as
before the fix, the board poses' rotation angles are off by up to 28 deg: on this scene the time-alignment
screen refuses it (13 of 14 motions); a milder lens could pass the gates with X off (the test accepts either).
"""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.config import load_settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.extrinsics.motion_synth import robot_arm_poses
from calibctl.core.synth.fisheye import FisheyeCamera, default_fisheye_distance_m, fisheye_poses
from calibctl.core.synth.pinhole import render_view
from calibctl.store.repository import Store
from calibctl.workflows.handeye import handeye_robot
from tests.artifacts.factories import calibration, measured_board
from tests.workflows.handeye.test_handeye_robot import POSE_COLUMNS, X_GRIPPER_CAM, pose_row

N_POSES = 15
FOV_DEG = (
    150.0  # the detector finds the board in every view on OpenCV 4.10 and 5.0 (tests/workflows/synth_folders)
)
SIGMAS = 4.0  # per translation axis: |error| within this many reported sigmas
WRONG_MM = 5.0  # the pinhole reading of the same lens misplaces X by more than this


def _camera() -> FisheyeCamera:
    return FisheyeCamera.from_fov((640, 480), FOV_DEG)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("fisheye-arm")
    board = measured_board()
    spec = BoardSpec.chessboard(board.cols, board.rows, board.measurement.square_size_m)
    camera, rng = _camera(), np.random.default_rng(5)
    T_cam_board = fisheye_poses(
        camera,
        spec.object_points(),
        N_POSES,
        rng,
        default_fisheye_distance_m(camera, spec.square_size_m),
        (15.0, 45.0),
        None,
        8.0,
    )
    T_base_gripper = robot_arm_poses(T_cam_board, X_GRIPPER_CAM, eye_in_hand=True)
    dark = camera.outside_circle()
    with (folder / "poses.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(POSE_COLUMNS)
        for i, (T_cb, T_bg) in enumerate(zip(T_cam_board, T_base_gripper, strict=True)):
            image = render_view(camera, spec, T_cb, rng)
            image[dark] = np.minimum(image[dark], 4)  # no light outside the image circle
            cv2.imwrite(str(folder / f"pose-{i:02d}.png"), image)
            writer.writerow(pose_row(f"pose-{i:02d}.png", T_bg))
    return folder


@pytest.fixture
def settings(sqlite_url: str):
    camera, base = _camera(), calibration(board=measured_board())
    art = base.model_copy(
        update={
            "camera_matrix": tuple(tuple(float(v) for v in row) for row in camera.K),
            "dist_coeffs": [float(v) for v in camera.dist],
            "model": base.model.model_copy(update={"name": "fisheye"}),
        }
    ).sealed()
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board())
        store.add_artifact(art, activate=True, actor="qa", station="test", reason="renderer's fisheye camera")
    return load_settings(db=sqlite_url)


def _translation_error_mm(result) -> np.ndarray:
    assert result.transform is not None, [g.message for g in result.gates]
    return (np.array(result.transform.translation_m) - X_GRIPPER_CAM[:3, 3]) * 1e3


def test_a_fisheye_camera_on_an_arm_is_solved_through_its_fisheye_model(scene, settings) -> None:
    result = handeye_robot.run_robot_handeye(
        settings, scene / "poses.csv", scene, "CAM-0001", "gripper", "camera"
    ).result
    assert result.status == "accepted" and not result.skipped, [g.message for g in result.gates]
    error = _translation_error_mm(result)
    assert result.uncertainty is not None
    assert np.all(np.abs(error) <= SIGMAS * np.array(result.uncertainty.sigma_translation_mm)), error
    R = se3.rotation_from_quaternion(np.array(result.transform.rotation_wxyz))
    assert np.degrees(se3.rotation_angle_rad(R.T @ X_GRIPPER_CAM[:3, :3])) < 0.1


def test_read_as_a_pinhole_the_same_fisheye_misplaces_x(
    scene, settings, monkeypatch: pytest.MonkeyPatch
) -> None:
    # What handeye did before: solvePnP with k1..k4 taken for k1 k2 p1 p2, whatever the model.
    def pinhole(obj, img, K, dist, model="k1k2"):
        return estimate_board_pose(obj, img, K, dist)

    monkeypatch.setattr(handeye_robot, "estimate_board_pose", pinhole)
    result = handeye_robot.run_robot_handeye(
        settings, scene / "poses.csv", scene, "CAM-0001", "gripper", "camera"
    ).result
    if result.status == "accepted":
        assert np.linalg.norm(_translation_error_mm(result)) > WRONG_MM
    else:  # or the gates see that no single X explains the warped poses
        assert any(not g.passed for g in result.gates)
