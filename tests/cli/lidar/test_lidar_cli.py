"""calibctl lidar solve / synth: wiring, exit codes, one-line errors naming the file and the fix."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.core.extrinsics import se3
from calibctl.core.lidar import solve as ls
from calibctl.core.lidar.target import BackingBoard
from calibctl.errors import NumericalError
from calibctl.workflows.lidar import lidar_solve as wf
from tests.datasets import ACFR, require_acfr

GRID = ["--cols", "5", "--rows", "7", "--square-mm", "95"]
BOARD = [*GRID, "--backing-mm", "610,850", "--pattern-offset-mm", "2,0"]
BOX = ["--box", "1,-2.2,-0.8,3.6,1.6,0.6"]
EMPTY_BOX = ["--box", "-5,-5,-1,-4,-4,1"]  # holds no board: every scan is no_plane


def invoke(args: list[str]):
    return CliRunner().invoke(app, args, terminal_width=200)


def acfr_subset(tmp_path: Path, poses: tuple[int, ...] = (1, 3, 5)) -> tuple[Path, Path]:
    require_acfr()
    img, pcd = tmp_path / "img", tmp_path / "pcd"
    img.mkdir()
    pcd.mkdir()
    for i in poses:
        (img / f"pose{i}.png").symlink_to(ACFR / "images" / f"pose{i}.png")
        (pcd / f"pose{i}.pcd").symlink_to(ACFR / "pcd" / f"pose{i}_full.pcd")
    return img, pcd


def solve_args(images: Path, scans: Path, *rest: str) -> list[str]:
    """`lidar solve` on these image and scan folders, then the rest of its options."""
    return ["lidar", "solve", "--images", str(images), "--scans", str(scans), *rest]


def camera(tmp_path: Path) -> list[str]:
    require_acfr()
    return ["--camera-info", str(ACFR / "camera_info.yaml")]


def test_a_malformed_box_is_exit_2(tmp_path: Path) -> None:
    res = invoke(solve_args(tmp_path, tmp_path, "--box", "1,2,3", "--camera-info", "x.yaml", *BOARD))
    assert res.exit_code == 2 and "--box '1,2,3' is not xmin" in res.output


def test_the_camera_is_given_exactly_once(tmp_path: Path) -> None:
    img, pcd = acfr_subset(tmp_path)
    res = invoke(solve_args(img, pcd, *BOX, *BOARD))
    assert res.exit_code == 2 and "exactly one of --camera-info FILE or --serial" in res.output


def test_a_camera_without_an_active_calibration_is_exit_2(tmp_path: Path) -> None:
    img, pcd = acfr_subset(tmp_path)
    url = f"sqlite:///{tmp_path / 'c.db'}"
    res = invoke(["--db", url, *solve_args(img, pcd, "--serial", "CAM-NONE", *BOX, *BOARD)])
    assert res.exit_code == 2 and "Error:" in res.output and "Traceback" not in res.output


def test_a_pattern_bigger_than_its_backing_board_is_exit_2(tmp_path: Path) -> None:
    img, pcd = acfr_subset(tmp_path)
    res = invoke(solve_args(img, pcd, *BOX, *camera(tmp_path), *GRID, "--backing-mm", "400,850"))
    assert res.exit_code == 2 and "does not fit on a 400 x 850 mm backing board" in res.output


def test_duplicate_frame_numbers_are_exit_2_naming_both(tmp_path: Path) -> None:
    img, pcd = acfr_subset(tmp_path)
    (pcd / "pose1_copy.pcd").symlink_to(ACFR / "pcd" / "pose1_target.pcd")
    res = invoke(solve_args(img, pcd, *BOX, *camera(tmp_path), *BOARD))
    assert res.exit_code == 2 and "two scans with frame number 1" in res.output


def test_a_lying_pcd_header_is_exit_2_naming_the_file_and_field(tmp_path: Path) -> None:
    img, pcd = acfr_subset(tmp_path)
    text = (ACFR / "pcd" / "pose3_full.pcd").read_text().replace("POINTS 24262", "POINTS 24000")
    (pcd / "pose3.pcd").unlink()
    (pcd / "pose3.pcd").write_text(text)
    res = invoke(solve_args(img, pcd, *BOX, *camera(tmp_path), *BOARD))
    assert res.exit_code == 2 and "pose3.pcd" in res.output and "WIDTH x HEIGHT" in res.output


def test_no_board_in_the_box_and_unpaired_files_are_outcomes_and_exit_1(tmp_path: Path) -> None:
    img, pcd = acfr_subset(tmp_path)
    (img / "pose99.png").symlink_to(ACFR / "images" / "pose7.png")
    res = invoke(solve_args(img, pcd, *EMPTY_BOX, *camera(tmp_path), *BOARD, "--json"))
    assert res.exit_code == 1
    doc = json.loads(res.stdout)
    outcomes = {(r["scan"] or r["image"]): r["outcome"] for r in doc["outcomes"]}
    assert outcomes == {
        "pose1.pcd": "no_plane",
        "pose3.pcd": "no_plane",
        "pose5.pcd": "no_plane",
        "pose99.png": "not_paired",
    }
    gate = doc["gates"][0]
    assert gate["gate"] == "lidar-poses" and not gate["passed"] and "capture 6 more poses" in gate["hint"]
    assert doc["transform"] is None


def test_a_set_of_boards_facing_one_way_is_refused_with_the_direction(tmp_path: Path) -> None:
    out = tmp_path / "oneway"
    assert invoke(["lidar", "synth", str(out), "--poses", "6", "--seed", "4", "--one-way"]).exit_code == 0
    truth = json.loads((out / "truth.json").read_text())
    res = invoke(
        solve_args(
            out / "images",
            out / "scans",
            "--box",
            truth["box"],
            "--camera-info",
            str(out / "camera_info.yaml"),
            *BOARD,
        )
    )
    assert res.exit_code == 1
    assert "gate lidar-observability FAIL" in res.output and "unobservable" in res.output
    assert "hint: tilt the board" in res.output and "no transform reported" in res.output


@pytest.mark.slow
def test_acfr_agrees_with_the_authors_and_its_halves_agree(tmp_path: Path) -> None:
    """The authors' numbers are T_lidar_cam (p_lidar = R p_cam + t, R = Rz(yaw) Ry(pitch) Rx(roll)):
    src/optimiser.cpp's RotationTranslation * camera point and include/.../optimiser.h Rotation::toMat."""
    require_acfr()
    res = invoke(
        solve_args(
            ACFR / "images",
            ACFR / "pcd",
            "--scan-pattern",
            "*_full.pcd",
            *BOX,
            *camera(tmp_path),
            *BOARD,
            "--json",
            "--tf-static",
            str(tmp_path / "tf.yaml"),
            "--overlay",
            str(tmp_path / "overlay"),
        )
    )
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert "child_frame_id: camera" in (tmp_path / "tf.yaml").read_text()
    assert len(doc["overlays"]) == 19 and (tmp_path / "overlay" / "pose1_lidar.png").stat().st_size > 0
    assert len(doc["outcomes"]) == 20 and all(r["outcome"] for r in doc["outcomes"])
    pub = np.loadtxt(ACFR / "published_calibration_quickstart.csv", delimiter=",", skiprows=1)
    mean, sd = pub.mean(axis=0), pub.std(axis=0, ddof=1)
    ours = np.array([*doc["transform"]["rpy_rad"], *doc["transform"]["translation_m"]])
    # measured (docs/lidar.md): roll -1.40, pitch -0.30, yaw -0.36, x +1.83, y +0.29, z +1.32 of their sd
    assert np.all(np.abs(ours - mean) < 2.5 * sd), (ours - mean) / sd
    # two disjoint halves (odd / even position) agree within 3 combined sigma
    req = wf.LidarRequest(
        ACFR / "images",
        ACFR / "pcd",
        BackingBoard(5, 7, 0.095, (0.61, 0.85), (0.002, 0.0)),
        wf.parse_box("1,-2.2,-0.8,3.6,1.6,0.6"),
        ACFR / "camera_info.yaml",
        scan_pattern="*_full.pcd",
    )
    poses, _ = wf.collect_poses(req, wf.load_lens(None, req.camera_info, None))  # type: ignore[arg-type]
    a, b = ls.solve(poses[0::2], req.board), ls.solve(poses[1::2], req.board)
    dt = a.T_lidar_cam[:3, 3] - b.T_lidar_cam[:3, 3]
    dr = se3.rotvec_from_rotation(a.T_lidar_cam[:3, :3] @ b.T_lidar_cam[:3, :3].T)
    assert np.all(np.abs(dt) < 3 * np.hypot(a.sigma_translation_m, b.sigma_translation_m))
    assert np.all(np.abs(dr) < 3 * np.radians(np.hypot(a.sigma_rotation_deg, b.sigma_rotation_deg)))


@pytest.fixture
def stored(sqlite_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_OPERATOR", "tester")

    def run(*args: str):
        return CliRunner().invoke(app, ["--db", sqlite_url, *args], terminal_width=200)

    return run


def test_a_board_registered_with_its_backing_is_the_solve_target(stored, tmp_path: Path) -> None:
    added = stored("board", "add", "L5", *BOARD)
    assert added.exit_code == 0, added.output
    shown = json.loads(stored("board", "show", "L5", "--json").stdout)
    assert shown["backing"] == {"width_m": 0.61, "height_m": 0.85, "pattern_offset_m": [0.002, 0.0]}
    assert "backing board 610" in stored("board", "show", "L5").output
    img, pcd = acfr_subset(tmp_path)
    res = stored(*solve_args(img, pcd, *EMPTY_BOX, *camera(tmp_path), "--board", "L5", "--json"))
    assert res.exit_code == 1  # the target was read; the empty box is the verdict
    assert json.loads(res.stdout)["outcome_counts"] == {"no_plane": 3}
    both = stored(*solve_args(img, pcd, *BOX, *camera(tmp_path), "--board", "L5", "--cols", "5"))
    assert both.exit_code == 2 and "not both" in both.output


def test_a_board_without_backing_dimensions_is_exit_2_naming_the_fix(stored, tmp_path: Path) -> None:
    assert stored("board", "add", "A17", *GRID).exit_code == 0
    img, pcd = acfr_subset(tmp_path)
    res = stored(*solve_args(img, pcd, *BOX, *camera(tmp_path), "--board", "A17"))
    assert res.exit_code == 2
    assert "board A17@1 was registered without its backing board dimensions" in res.output
    assert "--backing-mm W,H" in res.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--pattern-offset-mm", "2,0"], "--pattern-offset-mm needs --backing-mm"),
        (["--backing-mm", "400,850"], "does not fit on a 400 x 850 mm backing board"),
        (["--backing-mm", "610"], "is not two numbers"),
    ],
)
def test_bad_backing_options_of_board_add_are_exit_2(stored, args: list[str], message: str) -> None:
    res = stored("board", "add", "B1", *GRID, *args)
    assert res.exit_code == 2 and message in res.output


def _binary_pcd(points: np.ndarray) -> bytes:
    n = len(points)
    head = (
        f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
        f"POINTS {n}\nDATA binary\n"
    ).encode()
    return head + points.astype("<f4").tobytes()


def test_nan_points_are_counted_and_millimetre_scans_need_their_unit(tmp_path: Path) -> None:
    from calibctl.workflows.lidar.scans import read_scan

    img, pcd = acfr_subset(tmp_path, (1, 3))
    pts = read_scan(ACFR / "pcd" / "pose1_full.pcd").points_m
    with_nan = np.vstack([pts, np.full((7, 3), np.nan)])
    (pcd / "pose1.pcd").unlink()
    (pcd / "pose1.pcd").write_bytes(_binary_pcd(with_nan))
    res = invoke(solve_args(img, pcd, *EMPTY_BOX, *camera(tmp_path), *BOARD, "--json"))
    assert res.exit_code == 1
    rows = {r["scan"]: r for r in json.loads(res.stdout)["outcomes"]}
    assert rows["pose1.pcd"]["dropped_nonfinite"] == 7 and rows["pose3.pcd"]["dropped_nonfinite"] == 0
    (pcd / "pose3.pcd").unlink()
    np.savetxt(pcd / "pose3.txt", read_scan(ACFR / "pcd" / "pose3_full.pcd").points_m * 1000.0)
    res = invoke(solve_args(img, pcd, *BOX, *camera(tmp_path), *BOARD))
    assert res.exit_code == 2 and "pose3.txt" in res.output and "millimetres" in res.output
    assert "--scan-units mm" in res.output
    res = invoke(solve_args(img, pcd, *BOX, *camera(tmp_path), *BOARD, "--scan-units", "mm", "--json"))
    rows = {r["scan"]: r for r in json.loads(res.stdout)["outcomes"]}
    assert rows["pose3.txt"]["outcome"] == "accepted" and res.exit_code == 1  # 2 poses: too few for a solve


def test_tf_static_is_written_only_for_an_accepted_transform(tmp_path: Path) -> None:
    import yaml

    img, pcd = acfr_subset(tmp_path, (1, 3))
    target = tmp_path / "tf.yaml"
    res = invoke(solve_args(img, pcd, *EMPTY_BOX, *camera(tmp_path), *BOARD, "--tf-static", str(target)))
    assert res.exit_code == 1 and "not written" in res.output and not target.exists()
    accepted = {
        "status": "accepted",
        "images": "i",
        "scans": "s",
        "transform": {"translation_m": [0.07, 0.009, -0.157], "quaternion_wxyz": [0.5, -0.5, 0.5, -0.5]},
    }
    doc = yaml.safe_load(wf.tf_static_yaml(accepted, "velodyne", "camera_front"))
    edge = doc["transforms"][0]
    assert edge["header"]["frame_id"] == "velodyne" and edge["child_frame_id"] == "camera_front"
    assert edge["transform"]["rotation"] == {"x": -0.5, "y": 0.5, "z": -0.5, "w": 0.5}
    assert edge["transform"]["translation"]["z"] == -0.157


def test_synth_refuses_to_overwrite_a_rendered_set_without_force(tmp_path: Path) -> None:
    from calibctl.workflows.lidar.scans import read_scan

    out = tmp_path / "set"
    first = invoke(["lidar", "synth", str(out), "--poses", "1", "--seed", "3", "--json"])
    assert first.exit_code == 0
    cloud = read_scan(out / "scans" / "pose1.pcd")
    assert (
        len(cloud.points_m) > 25_000
        and cloud.ring is not None
        and set(np.unique(cloud.ring)) == set(range(16))
    )
    again = invoke(["lidar", "synth", str(out), "--poses", "1"])
    assert again.exit_code == 2 and "already holds a rendered set" in again.output
    assert invoke(["lidar", "synth", str(out), "--poses", "1", "--force"]).exit_code == 0


@pytest.fixture(scope="module")
def eight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("lidar") / "set"
    assert invoke(["lidar", "synth", str(out), "--poses", "8", "--seed", "1"]).exit_code == 0
    return out


@pytest.mark.parametrize("square_mm", ["9.5", "1", "50", "100"])
def test_any_square_size_solves_or_refuses_without_a_traceback(eight: Path, square_mm: str) -> None:
    truth = json.loads((eight / "truth.json").read_text())
    where = ["--images", str(eight / "images"), "--scans", str(eight / "scans"), "--box", truth["box"]]
    board = [a if a != "95" else square_mm for a in BOARD]
    res = invoke(["lidar", "solve", *where, "--camera-info", str(eight / "camera_info.yaml"), *board])
    assert res.exit_code in (1, 2) and "Traceback" not in res.output, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception


def test_a_solve_that_breaks_down_numerically_is_a_numerical_error(monkeypatch: pytest.MonkeyPatch) -> None:
    def singular(*_: object) -> None:
        raise np.linalg.LinAlgError("Matrix is not positive definite")

    monkeypatch.setattr(ls, "_solve", singular)
    board = BackingBoard(5, 7, 0.095, (0.61, 0.85))
    with pytest.raises(
        NumericalError, match="the camera-LiDAR solve broke down .Matrix is not positive definite"
    ):
        ls.solve([], board)
