"""Hand-eye on real photos: a stereo pair is two rigidly attached cameras, so A X = X B gives T_left_right.

Each camera's board poses (calibctl's solvePnP step, checked against a plain cv2.solvePnP) become a
poses CSV; ``calibctl handeye`` solves it and is compared with plain cv2.stereoCalibrate
(CALIB_FIX_INTRINSIC) on the same corners and intrinsics. Square size unknown in opencv-left-right:
lengths are in squares, for both tools alike.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.core.board.board_geometry import chessboard_object_points
from calibctl.core.capture.detect import detect_chessboard
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.extrinsics.handeye import Motions
from calibctl.core.extrinsics.handeye_gates import HandEyeThresholds, time_alignment_gate
from calibctl.workflows.handeye.handeye_io import write_motion_log
from tests.datasets import DATASETS, LEFT_RIGHT, needs_datasets

PAIRS = ["01", "02", "03", "04", "05", "06", "07", "08", "09", "11", "12", "13", "14"]
SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.001)


def _calibrate(object_points: np.ndarray, corners: list[np.ndarray], size: tuple[int, int]):
    _, K, dist, _, _ = cv2.calibrateCamera(
        [object_points.astype(np.float32)] * len(corners),
        [c.astype(np.float32) for c in corners],
        size,
        None,
        None,
    )
    return K, dist.ravel()


def _stereo_T_left_right(object_points, left, right, cal_left, cal_right, size) -> tuple[np.ndarray, float]:
    rms, *_, R, T, _, _ = cv2.stereoCalibrate(
        [object_points.astype(np.float32)] * len(left),
        [c.astype(np.float32) for c in left],
        [c.astype(np.float32) for c in right],
        *cal_left,
        *cal_right,
        size,
        flags=cv2.CALIB_FIX_INTRINSIC,
    )
    return se3.invert(se3.transform(R, T.ravel())), float(rms)  # OpenCV's (R, T) is T_right_left


@needs_datasets
def test_stereo_pair_as_hand_eye_agrees_with_plain_stereo_calibrate(tmp_path: Path) -> None:
    model = chessboard_object_points(9, 6, 1.0)
    corners: dict[str, list[np.ndarray]] = {"left": [], "right": []}
    for pair in PAIRS:
        for side in corners:
            gray = cv2.imread(str(LEFT_RIGHT / f"{side}{pair}.jpg"), cv2.IMREAD_GRAYSCALE)
            detection, reason = detect_chessboard(gray, 9, 6)
            assert detection is not None, f"{side}{pair}: {reason}"
            corners[side].append(detection.corners_px)
    size = (640, 480)
    cal = {side: _calibrate(model, corners[side], size) for side in corners}
    T_board_cam = {}
    for side in corners:
        poses = []
        for c in corners[side]:
            T_cam_board, rms_px = estimate_board_pose(model, c, *cal[side])
            assert T_cam_board is not None and rms_px < 1.0
            ok, rvec, tvec = cv2.solvePnP(model, c, *cal[side])  # the plain call
            np.testing.assert_allclose(
                T_cam_board, se3.transform(se3.rotation_from_rotvec(rvec.ravel()), tvec.ravel()), atol=1e-6
            )
            poses.append(se3.invert(T_cam_board))
        T_board_cam[side] = np.array(poses)
    log = write_motion_log(
        tmp_path / "stereo.csv",
        np.arange(len(PAIRS), dtype=float),
        T_board_cam["left"],
        T_board_cam["right"],
        force=False,
    )
    result = CliRunner().invoke(app, ["handeye", str(log), "--from", "left", "--to", "right", "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    t = np.array(doc["transform"]["translation_m"])
    sigma_t = np.array(doc["uncertainty"]["sigma_translation_mm"]) / 1e3
    R = se3.rotation_from_quaternion(np.array(doc["transform"]["rotation_wxyz"]))

    T_ref, rms_stereo = _stereo_T_left_right(
        model, corners["left"], corners["right"], cal["left"], cal["right"], size
    )
    assert rms_stereo < 0.5
    assert (
        abs(np.linalg.norm(t) / np.linalg.norm(T_ref[:3, 3]) - 1.0) < 5e-3
    )  # baseline within 0.5 % (0.27 % measured)
    assert np.all(np.abs(t - T_ref[:3, 3]) < 3.0 * sigma_t)  # the rest within 3 reported sigma
    assert np.degrees(se3.rotation_angle_rad(R.T @ T_ref[:3, :3])) < 0.25


@pytest.mark.slow
@needs_datasets
def test_unsynchronised_webcam_pairs_are_named_where_stereo_calibrate_returns_a_number() -> None:
    """baka-stereo: two USB webcams, a hand-held board. Plain OpenCV throughout (detection included)."""
    folder = DATASETS / "baka-stereo"
    model = chessboard_object_points(7, 10, 0.023)
    corners: dict[str, list[np.ndarray]] = {"left": [], "right": []}
    for stem in sorted(p.name.removeprefix("left_") for p in (folder / "left").glob("left_*.jpg")):
        found = {}
        for side in corners:
            gray = cv2.imread(str(folder / side / f"{side}_{stem}"), cv2.IMREAD_GRAYSCALE)
            ok, c = cv2.findChessboardCorners(
                gray, (7, 10), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
            )
            found[side] = cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), SUBPIX).reshape(-1, 2) if ok else None
        if all(v is not None for v in found.values()):
            for side in corners:
                corners[side].append(found[side])
    size = (1280, 720)
    cal = {side: _calibrate(model, corners[side], size) for side in corners}
    poses = {
        side: np.array([se3.invert(estimate_board_pose(model, c, *cal[side])[0]) for c in corners[side]])
        for side in corners
    }
    motions = Motions.from_poses(
        poses["left"], poses["right"], tuple(str(i) for i in range(len(corners["left"])))
    )
    gate = time_alignment_gate(motions, HandEyeThresholds())
    assert not gate.passed and len(gate.detail["mismatched_motions"]) >= len(corners["left"]) // 2
    _, rms_stereo = _stereo_T_left_right(
        model, corners["left"], corners["right"], cal["left"], cal["right"], size
    )
    assert rms_stereo > 5.0  # the plain tool answers anyway, with a reprojection error of pixels
