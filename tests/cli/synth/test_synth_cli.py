"""`calibctl synth`: wiring, files written, --json, and every way it refuses (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import detect_board
from calibctl.core.synth.pinhole import PinholeCamera

RUNNER = CliRunner()


def invoke(*args: str):
    return RUNNER.invoke(app, list(args), terminal_width=110)


def test_good_scenario_writes_images_and_truth(tmp_path: Path) -> None:
    out = tmp_path / "good"
    result = invoke("synth", str(out), "--scenario", "good", "--views", "4", "--seed", "2")
    assert result.exit_code == 0, result.output
    assert "wrote 4 images (4 views, 640x480, scenario good) and truth.json to" in result.stdout
    assert sorted(p.name for p in out.iterdir()) == ["truth.json", *[f"view-{i:03d}.png" for i in range(4)]]
    truth = json.loads((out / "truth.json").read_text())
    assert truth["schema"] == "calibctl.synth.truth/1"
    assert truth["camera"]["image_size"] == [640, 480]
    np.testing.assert_allclose(truth["camera"]["K"], PinholeCamera.seed_reference().K)
    assert truth["board"]["cols"] == 9 and truth["board"]["rows"] == 6
    view = truth["views"][0]
    assert view["file"] == "view-000.png" and len(view["corners_px"]) == 54
    assert 20.0 <= view["tilt_deg"] <= 40.0
    img = cv2.imread(str(out / "view-000.png"), cv2.IMREAD_UNCHANGED)
    assert img.shape == (480, 640) and img.dtype == np.uint8


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    for name in ("a", "b"):
        assert (
            invoke(
                "synth", str(tmp_path / name), "--views", "2", "--seed", "9", "--size", "320x240"
            ).exit_code
            == 0
        )
    assert (tmp_path / "a" / "view-001.png").read_bytes() == (tmp_path / "b" / "view-001.png").read_bytes()


def test_json_output_and_video(tmp_path: Path) -> None:
    out = tmp_path / "vid"
    result = invoke("synth", str(out), "--scenario", "video", "--views", "2", "--size", "320x240", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["files"] == ["video.avi"] and doc["scenario"] == "video" and doc["image_size"] == [320, 240]
    capture = cv2.VideoCapture(str(out / "video.avi"))
    frames = 0
    while capture.read()[0]:
        frames += 1
    capture.release()
    assert frames == doc["n_views"] == json.loads((out / "truth.json").read_text())["video"]["n_frames"]


def test_charuco_pattern(tmp_path: Path) -> None:
    out = tmp_path / "charuco"
    assert invoke("synth", str(out), "--pattern", "charuco", "--views", "1").exit_code == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["board"]["kind"] == "charuco" and truth["board"]["dictionary"] == "DICT_4X4_50"
    spec = BoardSpec.charuco(10, 7, 0.025, 0.018, "DICT_4X4_50")
    det, why = detect_board(cv2.imread(str(out / "view-000.png"), cv2.IMREAD_GRAYSCALE), spec)
    assert det is not None, why
    truth_px = np.array(truth["views"][0]["corners_px"])[det.corner_ids]
    assert np.linalg.norm(det.corners_px - truth_px, axis=1).mean() < 0.1


def test_refuses_a_non_empty_folder_without_force(tmp_path: Path) -> None:
    out = tmp_path / "busy"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    result = invoke("synth", str(out), "--views", "2")
    assert result.exit_code == 2
    assert f"Error: {out} is not empty" in result.stderr
    assert "Hint: choose an empty or new folder, or pass --force" in result.stderr
    result = invoke("synth", str(out), "--views", "2", "--force")
    assert result.exit_code == 0, result.output
    assert (out / "notes.txt").read_text() == "keep me"  # --force replaces synth files only
    # a second forced run with fewer views leaves no stale view from the first
    assert invoke("synth", str(out), "--views", "1", "--force").exit_code == 0
    assert sorted(p.name for p in out.glob("view-*.png")) == ["view-000.png"]


def test_refuses_a_file_as_out(tmp_path: Path) -> None:
    target = tmp_path / "file.txt"
    target.write_text("x")
    result = invoke("synth", str(target))
    assert result.exit_code == 2 and f"Error: {target} exists and is not a folder" in result.stderr


def test_bad_size_and_views_exit_2(tmp_path: Path) -> None:
    result = invoke("synth", str(tmp_path / "x"), "--size", "640by480")
    assert result.exit_code == 2 and "Error: --size must look like 640x480, got '640by480'" in result.stderr
    result = invoke("synth", str(tmp_path / "x"), "--size", "64x48")
    assert result.exit_code == 2 and "out of range" in result.stderr
    result = invoke("synth", str(tmp_path / "x"), "--views", "0")
    assert result.exit_code == 2 and "Error: --views must be between 1 and 500, got 0" in result.stderr
    assert not (tmp_path / "x").exists()


def test_unknown_scenario_is_a_usage_error(tmp_path: Path) -> None:
    result = invoke("synth", str(tmp_path / "x"), "--scenario", "sideways")
    assert result.exit_code == 2 and "'sideways' is not one of" in result.stderr


def test_a_scenario_that_cannot_be_staged_exits_2(tmp_path: Path) -> None:
    # 'centre' puts the whole board in the middle ninth; at 160x120 its squares would be < 11 px
    result = invoke("synth", str(tmp_path / "x"), "--scenario", "centre", "--size", "160x120")
    assert result.exit_code == 2
    assert "Error: cannot stage scenario 'centre' at 160x120" in result.stderr
    assert not (tmp_path / "x").exists()


def test_fisheye_renders_an_image_circle_with_truth_the_detector_agrees_with(tmp_path: Path) -> None:
    out = tmp_path / "fisheye"
    result = invoke(
        "synth", str(out), "--fisheye", "185", "--views", "3", "--seed", "1", "--size", "1024x768"
    )
    assert result.exit_code == 0, result.output
    truth = json.loads((out / "truth.json").read_text())
    cam = truth["camera"]
    assert cam["fov_deg"] == 185 and len(cam["dist"]) == 4 and "equidistant" in cam["model"]
    img = cv2.imread(str(out / "view-000.png"), cv2.IMREAD_GRAYSCALE)
    assert img[0, 0] <= 4 and img[-1, -1] <= 4  # the corners of the frame are outside the image circle
    spec = BoardSpec.chessboard(9, 6, 0.025)
    errors = []
    for view in truth["views"]:
        det, why = detect_board(cv2.imread(str(out / view["file"]), cv2.IMREAD_GRAYSCALE), spec)
        assert det is not None, why
        errors.append(
            np.linalg.norm(det.corners_px - np.array(view["corners_px"])[det.corner_ids], axis=1).mean()
        )
    assert max(errors) < 0.15


def test_fisheye_refuses_a_field_of_view_it_cannot_render_and_other_scenarios(tmp_path: Path) -> None:
    result = invoke("synth", str(tmp_path / "a"), "--fisheye", "250")
    assert result.exit_code == 2 and "60-190 deg, got 250" in result.output
    result = invoke("synth", str(tmp_path / "b"), "--fisheye", "170", "--scenario", "flat")
    assert result.exit_code == 2 and "good scenario only" in result.output
