"""Robot-arm hand-eye on rendered board photos: camera on a gripper (and fixed in the cell), 15 arm poses.

The camera's active calibration sits in a store; calibctl detects the board in every image, solves
T_cam_board with solvePnP on that calibration and then A X = X B. The bar: X within 1 mm and
0.1 deg of the truth the renderer used.
"""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.motion_synth import robot_arm_poses
from calibctl.core.synth.pinhole import PinholeCamera, render_view
from calibctl.core.synth.scenes import scenario_poses
from calibctl.errors import InputError, NotFoundError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.handeye.handeye_robot import run_robot_handeye
from tests.artifacts.factories import calibration, measured_board

N_POSES = 15
X_GRIPPER_CAM = se3.transform(
    se3.rotation_from_rotvec(np.radians([4.0, -3.0, 90.0])), np.array([0.05, -0.03, 0.10])
)
X_BASE_CAM = se3.transform(
    se3.rotation_from_rotvec(np.radians([150.0, 10.0, 5.0])), np.array([0.8, 0.2, 0.9])
)
TOL_MM, TOL_DEG = 1.0, 0.1
POSE_COLUMNS = ["image", *(f"gripper_q{c}" for c in "wxyz"), *(f"gripper_t{c}_m" for c in "xyz")]


def pose_row(image: str, T_base_gripper: np.ndarray) -> list[str]:
    """One row of the robot pose CSV (POSE_COLUMNS): the image and the gripper's pose in the base frame, m."""
    q = se3.quaternion_from_rotation(T_base_gripper[:3, :3])
    return [image, *(repr(float(v)) for v in q), *(repr(float(v)) for v in T_base_gripper[:3, 3])]


def _camera() -> PinholeCamera:
    art = calibration(cx=319.5, cy=239.5)  # the renderer's K: centre of a 640x480 pixel grid
    return PinholeCamera(np.array(art.camera_matrix), np.array(art.dist_coeffs), tuple(art.image_size))


def _write_scene(folder: Path, eye_in_hand: bool, seed: int) -> Path:
    board = measured_board()
    spec = BoardSpec.chessboard(board.cols, board.rows, board.measurement.square_size_m)
    rng = np.random.default_rng(seed)
    T_cam_board = scenario_poses("good", _camera(), spec, N_POSES, rng)
    X = X_GRIPPER_CAM if eye_in_hand else X_BASE_CAM
    T_fixed = None if eye_in_hand else se3.transform(np.eye(3), np.array([0.0, 0.0, 0.12]))
    T_base_gripper = robot_arm_poses(T_cam_board, X, eye_in_hand=eye_in_hand, T_fixed=T_fixed)
    folder.mkdir()
    with (folder / "poses.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(POSE_COLUMNS)
        for i, (T_cb, T_bg) in enumerate(zip(T_cam_board, T_base_gripper, strict=True)):
            name = f"pose-{i:02d}.png"
            cv2.imwrite(str(folder / name), render_view(_camera(), spec, T_cb, rng))
            writer.writerow(pose_row(name, T_bg))
    return folder


@pytest.fixture(scope="module")
def scenes(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("robot")
    return {
        "in-hand": _write_scene(root / "in-hand", True, 3),
        "to-hand": _write_scene(root / "to-hand", False, 4),
    }


@pytest.fixture
def settings(sqlite_url: str):
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board())
        store.add_artifact(
            calibration(cx=319.5, cy=239.5, board=measured_board()),
            activate=True,
            actor="qa",
            station="test",
            reason="renderer's camera",
        )
    return load_settings(db=sqlite_url)


def _errors(result, X: np.ndarray) -> tuple[float, float]:
    assert result.transform is not None
    t = np.array(result.transform.translation_m)
    R = se3.rotation_from_quaternion(np.array(result.transform.rotation_wxyz))
    return float(np.linalg.norm(t - X[:3, 3]) * 1e3), float(
        np.degrees(se3.rotation_angle_rad(R.T @ X[:3, :3]))
    )


def _handeye_cli(
    settings, poses: Path, images: Path, serial: str, *extra: str, frames=("gripper", "camera"), **kw
):
    """`calibctl handeye` of this pose file and image folder, for a camera of the store."""
    source, target = frames
    options = ["--from", source, "--to", target, "--images", str(images), "--serial", serial]
    return CliRunner().invoke(app, ["--db", settings.db_url, "handeye", str(poses), *options, *extra], **kw)


@pytest.mark.parametrize("method", ["park", "tsai"])
def test_eye_in_hand_recovers_x_within_1_mm_and_0_1_deg(scenes, settings, method) -> None:
    d = scenes["in-hand"]
    outcome = run_robot_handeye(settings, d / "poses.csv", d, "CAM-0001", "gripper", "camera", method=method)
    result = outcome.result
    assert result.status == "accepted", [g.message for g in result.gates]
    error_mm, error_deg = _errors(result, X_GRIPPER_CAM)
    assert error_mm < TOL_MM and error_deg < TOL_DEG
    assert result.provenance.camera == "CAM-0001@1" and result.provenance.board == "A17@1"
    assert len(result.provenance.input_image_sha256) == N_POSES and len(result.motions) == N_POSES - 1


def test_eye_to_hand_recovers_x_within_1_mm_and_0_1_deg(scenes, settings) -> None:
    d = scenes["to-hand"]
    result = run_robot_handeye(
        settings, d / "poses.csv", d, "CAM-0001", "base", "camera", eye_to_hand=True
    ).result
    assert result.status == "accepted", [g.message for g in result.gates]
    assert result.provenance.input_shape == "robot-eye-to-hand"
    error_mm, error_deg = _errors(result, X_BASE_CAM)
    assert error_mm < TOL_MM and error_deg < TOL_DEG


def test_the_wrong_mode_is_rejected_by_the_consistency_gate(scenes, settings) -> None:
    d = scenes["to-hand"]  # eye-to-hand data solved as eye-in-hand: same angles, no single X
    result = run_robot_handeye(settings, d / "poses.csv", d, "CAM-0001", "gripper", "camera").result
    assert result.status == "rejected" and result.transform is None and result.uncertainty is None
    gates = {g.gate: g for g in result.gates}
    assert gates["rotation"].passed and gates["lever-arm"].passed and gates["time-alignment"].passed
    assert not gates["consistency"].passed and gates["consistency"].value > 1.0
    assert gates["consistency"].message.startswith("motions inconsistent with one rigid transform")
    assert "--eye-in-hand vs --eye-to-hand" in gates["consistency"].hint
    accepted = run_robot_handeye(
        settings, d / "poses.csv", d, "CAM-0001", "base", "camera", eye_to_hand=True
    ).result
    assert next(g for g in accepted.gates if g.gate == "consistency").value < 0.1


def test_a_camera_with_no_active_calibration_is_exit_2(scenes, settings) -> None:
    d = scenes["in-hand"]
    with pytest.raises(NotFoundError, match="CAM-0404"):
        run_robot_handeye(settings, d / "poses.csv", d, "CAM-0404", "gripper", "camera")
    result = _handeye_cli(settings, d / "poses.csv", d, "CAM-0404")
    assert result.exit_code == 2 and "CAM-0404" in result.stderr and "Traceback" not in result.output


def test_a_camera_whose_capture_was_rejected_is_named_as_such_not_unknown(scenes, settings) -> None:
    from tests.store.documents import capture_session

    with Store.open(settings.db_url) as store:
        store.add_session(capture_session("aaaaaaaaaaa1", serial="CAM-0002", status="rejected"))
    d = scenes["in-hand"]
    result = _handeye_cli(settings, d / "poses.csv", d, "CAM-0002", terminal_width=200)
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "unknown serial" not in result.stderr
    assert (
        "no calibration is stored for 'CAM-0002': its capture sessions were rejected at the gates"
        in result.stderr
    )
    assert "calibctl calibrate --serial CAM-0002" in result.stderr


def test_robot_poses_in_millimetres_are_named(scenes, settings, tmp_path: Path) -> None:
    d = scenes["in-hand"]
    rows = list(csv.reader((d / "poses.csv").open()))
    for row in rows[1:]:
        row[5:8] = [str(float(v) * 1000) for v in row[5:8]]
    bad = tmp_path / "mm.csv"
    with bad.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    with pytest.raises(InputError, match="beyond any arm's reach in metres: millimetres"):
        run_robot_handeye(settings, bad, d, "CAM-0001", "gripper", "camera")


def test_a_missing_image_names_file_and_line(scenes, settings, tmp_path: Path) -> None:
    d = scenes["in-hand"]
    text = (d / "poses.csv").read_text().replace("pose-04.png", "pose-99.png")
    (tmp_path / "p.csv").write_text(text)
    with pytest.raises(InputError, match=r"p.csv line 6: cannot read image .*pose-99.png"):
        run_robot_handeye(settings, tmp_path / "p.csv", d, "CAM-0001", "gripper", "camera")


def test_cli_wiring_with_tf_static(scenes, settings, tmp_path: Path) -> None:
    d = scenes["in-hand"]
    result = _handeye_cli(
        settings,
        d / "poses.csv",
        d,
        "CAM-0001",
        "--tf-static",
        str(tmp_path / "tf.yaml"),
        frames=("tool0", "camera_optical"),
        terminal_width=110,
    )
    assert result.exit_code == 0, result.output
    assert "robot-eye-in-hand" in result.stdout and "Result: ACCEPTED" in result.stdout
    assert "child_frame_id: camera_optical" in (tmp_path / "tf.yaml").read_text()


def test_robot_input_problems_are_exit_2_naming_what(scenes, settings, tmp_path: Path) -> None:
    d = scenes["in-hand"]
    csv_path = d / "poses.csv"
    with pytest.raises(UsageError, match="needs both --images DIR and --serial SERIAL"):
        run_robot_handeye(settings, csv_path, d, None, "gripper", "camera")
    with pytest.raises(InputError, match="is not a folder"):
        run_robot_handeye(settings, csv_path, tmp_path / "nowhere", "CAM-0001", "gripper", "camera")
    with pytest.raises(UsageError, match="not a board reference"):
        run_robot_handeye(settings, csv_path, d, "CAM-0001", "gripper", "camera", board_ref="A17@x")

    no_image = tmp_path / "no_image.csv"
    no_image.write_text(csv_path.read_text().replace("image,", "picture,", 1))
    with pytest.raises(InputError, match="no_image.csv has no image column"):
        run_robot_handeye(settings, no_image, d, "CAM-0001", "gripper", "camera")


def test_unreadable_or_wrong_size_images_are_named(scenes, settings, tmp_path: Path) -> None:
    d = scenes["in-hand"]
    images = tmp_path / "images"
    images.mkdir()
    for p in d.glob("*.png"):
        (images / p.name).write_bytes(p.read_bytes())
    (images / "pose-02.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match=r"line 4: .*pose-02.png is not a readable image"):
        run_robot_handeye(settings, d / "poses.csv", images, "CAM-0001", "gripper", "camera")
    small = cv2.resize(cv2.imread(str(d / "pose-02.png"), cv2.IMREAD_GRAYSCALE), (320, 240))
    cv2.imwrite(str(images / "pose-02.png"), small)
    with pytest.raises(InputError, match="pose-02.png is 320x240 but CAM-0001@1 was fitted at 640x480"):
        run_robot_handeye(settings, d / "poses.csv", images, "CAM-0001", "gripper", "camera")


def test_images_without_a_board_are_skipped_and_too_few_left_is_exit_2(
    scenes, settings, tmp_path: Path
) -> None:
    d = scenes["in-hand"]
    images = tmp_path / "images"
    images.mkdir()
    blank = np.full((480, 640), 128, np.uint8)
    for i, p in enumerate(sorted(d.glob("*.png"))):
        (images / p.name).write_bytes(p.read_bytes() if i != 5 else cv2.imencode(".png", blank)[1].tobytes())
    result = run_robot_handeye(settings, d / "poses.csv", images, "CAM-0001", "gripper", "camera").result
    assert (
        result.status == "accepted"
        and len(result.skipped) == 1
        and result.skipped[0].startswith("pose-05.png")
    )
    for p in images.glob("*.png"):
        cv2.imwrite(str(p), blank)
    with pytest.raises(InputError, match="the board was found in 0 of 15 images"):
        run_robot_handeye(settings, d / "poses.csv", images, "CAM-0001", "gripper", "camera")


def _pose_rows(d: Path) -> list[np.ndarray]:
    """The scene's T_base_gripper per image, in image-name order, from its CSV."""
    rows = list(csv.DictReader((d / "poses.csv").open()))
    out = []
    for row in sorted(rows, key=lambda r: r["image"]):
        q = np.array([float(row[f"gripper_q{c}"]) for c in "wxyz"])
        out.append(
            se3.transform(se3.rotation_from_quaternion(q), [float(row[f"gripper_t{c}_m"]) for c in "xyz"])
        )
    return out


def _write_vec(path: Path, poses: list[np.ndarray], sep: str = "\t") -> Path:
    path.write_text("".join(sep.join(f"{v:.12f}" for v in T.ravel()) + "\n" for T in poses))
    return path


@pytest.mark.parametrize("sep", ["\t", ",", "  "])
def test_a_headerless_file_of_16_numbers_per_line_is_read_in_image_order(
    scenes, settings, tmp_path, sep
) -> None:
    # RWHE-Calib's RobotPosesVec.txt layout: one row-major 4x4 T_base_gripper (metres) per image, no names
    d = scenes["in-hand"]
    vec = _write_vec(tmp_path / "RobotPosesVec.txt", _pose_rows(d), sep)
    got = run_robot_handeye(settings, vec, d, "CAM-0001", "gripper", "camera").result
    want = run_robot_handeye(settings, d / "poses.csv", d, "CAM-0001", "gripper", "camera").result
    assert got.status == "accepted" and got.transform is not None and want.transform is not None
    np.testing.assert_allclose(got.transform.translation_m, want.transform.translation_m, atol=1e-9)
    assert [m.label for m in got.motions] == [m.label for m in want.motions]  # the same images, paired alike


def test_a_headerless_pose_file_is_checked_line_by_line(scenes, settings, tmp_path) -> None:
    d = scenes["in-hand"]
    poses = _pose_rows(d)
    vec = tmp_path / "p.txt"
    vec.write_text("".join(" ".join("1" for _ in range(12)) + "\n" for _ in poses))
    with pytest.raises(
        InputError, match=r"p.txt line 1: 12 numbers; a pose file without a header has 16 per line"
    ):
        run_robot_handeye(settings, vec, d, "CAM-0001", "gripper", "camera")
    bad = [T.copy() for T in poses]
    bad[3][0, 3] = np.nan
    with pytest.raises(InputError, match=r"p.txt: non-finite numbers \(nan or inf\) at line 4"):
        run_robot_handeye(settings, _write_vec(vec, bad), d, "CAM-0001", "gripper", "camera")
    bad = [T.copy() for T in poses]
    bad[2][:3, :3] *= 1.01
    with pytest.raises(InputError, match=r"p.txt: rotation block not a rotation at line 3"):
        run_robot_handeye(settings, _write_vec(vec, bad), d, "CAM-0001", "gripper", "camera")
    with pytest.raises(InputError, match=r"the 4x4 does not end in 0 0 0 1 at lines 1, 2"):
        run_robot_handeye(settings, _write_vec(vec, [T.T for T in poses]), d, "CAM-0001", "gripper", "camera")
    with pytest.raises(InputError, match=r"p.txt has 14 poses but .* has 15 images"):
        run_robot_handeye(settings, _write_vec(vec, poses[:-1]), d, "CAM-0001", "gripper", "camera")
    text = _write_vec(vec, poses).read_text().splitlines()
    vec.write_text("\n".join([*text[:5], "1 2 three 4", *text[5:]]) + "\n")
    with pytest.raises(InputError, match=r"p.txt line 6: not all numbers"):
        run_robot_handeye(settings, vec, d, "CAM-0001", "gripper", "camera")
    result = _handeye_cli(settings, _write_vec(vec, poses[:-1]), d, "CAM-0001")
    assert result.exit_code == 2 and "14 poses but" in result.stderr and "Traceback" not in result.output


def test_a_mismatch_on_a_static_pose_arm_does_not_send_the_user_to_timeoffset(scenes, settings) -> None:
    """The arm stops for each photo, so a time offset cannot turn the camera more than the gripper;
    the pose file shifted one row against the images is (the pairing, not the clock)."""
    d = scenes["in-hand"]
    rows = list(csv.reader((d / "poses.csv").open(newline="")))
    header, body = rows[0], rows[1:]
    shifted = [[body[i][0], *body[(i + 1) % len(body)][1:]] for i in range(len(body))]
    path = d / "poses-shifted.csv"
    with path.open("w", newline="") as handle:
        csv.writer(handle).writerows([header, *shifted])
    result = run_robot_handeye(settings, path, d, "CAM-0001", "gripper", "camera").result
    gate = next(g for g in result.gates if g.gate == "time-alignment")
    assert result.status == "rejected" and not gate.passed
    assert (
        "timeoffset" not in gate.hint
        and "held still" in gate.hint
        and "pairs a photo with the pose" in gate.hint
    )


def test_a_mismatch_in_a_log_in_time_still_names_the_time_offset() -> None:
    from calibctl.core.extrinsics.handeye import Motions
    from calibctl.core.extrinsics.handeye_gates import HandEyeThresholds, time_alignment_gate
    from calibctl.core.extrinsics.motion_synth import synthesize_pose_log

    log = synthesize_pose_log(X_GRIPPER_CAM, 30, time_offset_s=0.08, seed=5)
    motions = Motions.from_poses(log.T_first, log.T_second, tuple(str(i) for i in range(len(log.T_first))))
    assert "calibctl timeoffset" in time_alignment_gate(motions, HandEyeThresholds()).hint
    assert "timeoffset" not in time_alignment_gate(motions, HandEyeThresholds(), static_poses=True).hint
