"""calibctl lidar solve's messages name the real mistake: a non-regular scan file, non-finite sweeps, a fold
count over the poses, an illegal tf frame name (one rendered 8-pose set, shared by the module)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.workflows.lidar.lidar_synth import run_lidar_synth

BOARD = ["--cols", "5", "--rows", "7", "--square-mm", "95", "--backing-mm", "610,850"]
POSES = 8


@pytest.fixture(scope="module")
def lidar_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("lidar-messages") / "set"
    run_lidar_synth(root, POSES, 0, 0.0, False, False)
    return root


def _scans(lidar_set: Path, where: Path) -> Path:
    """A scans folder of links to the rendered sweeps, to be spoiled by a test."""
    where.mkdir()
    for scan in sorted((lidar_set / "scans").iterdir()):
        (where / scan.name).symlink_to(scan)
    return where


def solve(lidar_set: Path, *extra: str, scans: Path | None = None):
    truth = json.loads((lidar_set / "truth.json").read_text())
    offset = ",".join(f"{v:g}" for v in truth["board"]["pattern_offset_mm"])
    args = [
        "lidar",
        "solve",
        "--images",
        str(lidar_set / "images"),
        "--scans",
        str(scans or lidar_set / "scans"),
    ]
    args += ["--box", truth["box"], "--camera-info", str(lidar_set / "camera_info.yaml"), *BOARD]
    return CliRunner().invoke(app, [*args, "--pattern-offset-mm", offset, *extra], terminal_width=200)


@pytest.mark.parametrize("kind", ["fifo", "folder", "loop"])
def test_a_scan_that_is_not_a_regular_file_is_named_so(lidar_set: Path, tmp_path: Path, kind: str) -> None:
    scans = _scans(lidar_set, tmp_path / "scans")
    (scans / "pose1.pcd").unlink()
    if kind == "fifo":
        os.mkfifo(scans / "pose1.pcd")
    elif kind == "folder":
        (scans / "pose1.pcd").mkdir()
    else:
        (scans / "pose1.pcd").symlink_to(scans / "pose1.pcd")
    res = solve(lidar_set, scans=scans)
    assert res.exit_code == 2, res.output
    assert f"the scan {scans / 'pose1.pcd'} is a" in res.stderr and "not a regular file" in res.stderr
    assert "no scan with this frame number" not in res.output


def test_an_all_nan_sweep_is_named_non_finite_not_an_empty_box(lidar_set: Path, tmp_path: Path) -> None:
    scans = _scans(lidar_set, tmp_path / "scans")
    header, _, body = (lidar_set / "scans" / "pose1.pcd").read_text().partition("DATA ascii\n")
    (scans / "pose1.pcd").unlink()
    rows = sum(1 for line in body.splitlines() if line.strip())
    (scans / "pose1.pcd").write_text(header + "DATA ascii\n" + "nan nan nan 0 0\n" * rows)
    res = solve(lidar_set, "--json", scans=scans)
    row = next(r for r in json.loads(res.stdout)["outcomes"] if r["scan"] == "pose1.pcd")
    assert row["outcome"] == "no_plane" and row["dropped_nonfinite"] == rows
    assert f"all {rows} points of the sweep are non-finite (NaN or inf)" in row["message"]
    assert "inside the station box" not in row["message"]


def test_more_folds_than_poses_runs_leave_one_out_and_says_so(lidar_set: Path) -> None:
    res = solve(lidar_set, "--folds", "100")
    assert res.exit_code in (0, 1), res.output
    assert f"{POSES}-fold" in res.stdout and "100-fold" not in res.stdout
    assert f"--folds 100 is more than the {POSES} accepted poses" in res.stdout
    assert f"give --folds {POSES} or fewer" in res.stdout


def test_an_illegal_lidar_frame_is_refused_before_tf_static_is_written(
    lidar_set: Path, tmp_path: Path
) -> None:
    tf = tmp_path / "tf.yaml"
    res = solve(lidar_set, "--lidar-frame", "bad name!", "--tf-static", str(tf))
    assert res.exit_code == 2, res.output
    assert "--lidar-frame 'bad name!' is not a legal ROS frame name" in res.stderr
    assert not tf.exists()


def test_a_board_the_images_do_not_show_names_the_one_they_do(lidar_set: Path, tmp_path: Path) -> None:
    images, scans = tmp_path / "images", tmp_path / "scans"
    images.mkdir()
    scans.mkdir()
    for i in (1, 4, 7):  # three pairs: the refusal needs no solve
        (images / f"pose{i}.png").symlink_to(lidar_set / "images" / f"pose{i}.png")
        (scans / f"pose{i}.pcd").symlink_to(lidar_set / "scans" / f"pose{i}.pcd")
    truth = json.loads((lidar_set / "truth.json").read_text())
    args = ["lidar", "solve", "--images", str(images), "--scans", str(scans), "--box", truth["box"]]
    args += ["--camera-info", str(lidar_set / "camera_info.yaml"), "--cols", "9", "--rows", "6"]
    res = CliRunner().invoke(app, [*args, "--square-mm", "50", "--backing-mm", "610,850"])
    assert res.exit_code == 2, res.output
    assert "no 9x6 chessboard (given as --cols 9 --rows 6)" in res.stderr
    assert "a 7x5 chessboard is visible in" in res.stderr and "check --cols/--rows" in res.stderr
    assert "more poses" not in res.output


def _camera_info(lidar_set: Path, where: Path, old: str, new: str) -> Path:
    text = (lidar_set / "camera_info.yaml").read_text()
    assert old in text
    where.write_text(text.replace(old, new))
    return where


def test_a_camera_info_with_k_all_zeros_is_named_uncalibrated(lidar_set: Path, tmp_path: Path) -> None:
    k = next(
        line for line in (lidar_set / "camera_info.yaml").read_text().splitlines() if line.startswith("K:")
    )
    info = _camera_info(lidar_set, tmp_path / "zero.yaml", k, "K: [0, 0, 0, 0, 0, 0, 0, 0, 0]")
    res = solve(lidar_set, "--camera-info", str(info))
    assert res.exit_code == 2, res.output
    assert "K is no camera matrix (fx 0, fy 0" in res.stderr and "the camera is not calibrated" in res.stderr
    assert "more poses" not in res.output


def test_a_square_size_off_the_board_names_the_size_the_camera_and_lidar_agree_on(lidar_set: Path) -> None:
    res = solve(lidar_set, "--square-mm", "100", "--json")
    doc = json.loads(res.stdout)
    hints = [g["hint"] for g in doc["gates"] if g["hint"]]
    if res.exit_code == 0:  # every gate passed: the suspicion is a note
        hints = doc["notes"]
    assert len(hints) == 1 and "not the 100 mm given; check --square-mm" in hints[0], doc["gates"]
    assert "squares look 9" in hints[0] and "more, varied poses" not in res.stdout


def test_the_right_square_size_raises_no_suspicion(lidar_set: Path) -> None:
    res = solve(lidar_set, "--json")
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["notes"] == []


def test_a_lens_model_the_images_do_not_fit_is_named(lidar_set: Path, tmp_path: Path) -> None:
    info = _camera_info(lidar_set, tmp_path / "fisheye.yaml", "plumb_bob", "equidistant")
    d = next(line for line in info.read_text().splitlines() if line.startswith("D:"))
    info.write_text(info.read_text().replace(d, "D: [0, 0, 0, 0]"))
    res = solve(lidar_set, "--camera-info", str(info), "--json")
    doc = json.loads(res.stdout)
    hints = [g["hint"] for g in doc["gates"] if g["hint"]] or doc["notes"]
    assert len(hints) == 1 and "do not match that lens or its model" in hints[0], doc["gates"]
    assert "(fisheye, " in hints[0] and "more, varied poses" not in res.stdout
