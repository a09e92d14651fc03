"""`calibctl rig solve-folders` and `calibctl synth --rig`: wiring, exit codes, messages, --json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from tests.datasets import BAKA_STEREO, LEFT_RIGHT, needs_datasets
from tests.workflows.rig_folders_data import rendered_rig, rig_sources, split_pairs, true_baseline_mm

RUNNER = CliRunner()


def invoke(*args: str):
    return RUNNER.invoke(app, list(args), terminal_width=110)


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


def _sources(rig2: Path, cam1: Path | None = None) -> list[str]:
    return [*rig_sources(rig2, cam1), "--cols", "9", "--rows", "6", "--square-mm", "25"]


def test_solve_folders_reports_the_tree_and_writes_exports(rig2, tmp_path):
    result = invoke("rig", "solve-folders", *_sources(rig2), "--export-dir", str(tmp_path / "out"))
    assert result.exit_code == 0, result.output
    assert "T_CAM0_CAM1: |t| = 75." in result.output and "gate rig-connected pass" in result.output
    assert "held-out epipolar RMS" in result.output and "verdict: pass" in result.output
    assert {p.name for p in (tmp_path / "out").iterdir()} == {
        "stereo_CAM0_CAM1.yaml",
        "tf_static.yaml",
        "rig.urdf.xml",
        "camchain.yaml",
        "CAM0_camera_info.yaml",
        "CAM1_camera_info.yaml",
    }


def test_solve_folders_exports_carry_a_not_stored_trace_header_that_lint_reads(rig2, tmp_path):
    """Like a stored rig's exports, each names what it came from: no rig version (not stored), the verdict and
    the solution's sha256; lint checks each file's hash and passes them with a traceability warning."""
    out = tmp_path / "out"
    result = invoke("--json", "rig", "solve-folders", *_sources(rig2), "--export-dir", str(out))
    assert result.exit_code == 0, result.output
    sha = json.loads(result.output)["solution_sha256"]
    line = f"calibctl rig not stored (rig solve-folders) accepted solution-sha256 {sha}"
    paths = sorted(out.iterdir())
    for path in paths:
        head = path.read_text().splitlines()[:3]
        assert any(text.strip("#<>!- ") == line for text in head), (path.name, head)
    linted = invoke("--json", "lint", *map(str, paths))
    assert linted.exit_code == 0, linted.output
    results = json.loads(linted.output)["results"]
    assert all({f["rule"] for f in r["findings"]} == {"traceability"} for r in results), results
    assert all("not from a stored rig version" in r["findings"][0]["message"] for r in results)
    edited = out / "tf_static.yaml"
    edited.write_text(edited.read_text().replace("x: ", "x: 1", 1))
    linted = invoke("--json", "lint", str(edited))
    assert linted.exit_code == 1 and "content-hash" in linted.output


def test_solve_folders_json_and_root(rig2):
    result = invoke("--json", "rig", "solve-folders", *_sources(rig2), "--root", "CAM1")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert doc["root"] == "CAM1" and doc["tree"][0]["child"] == "CAM0"
    assert (
        abs(doc["tree"][0]["translation_mm"] - true_baseline_mm(rig2))
        < 3 * doc["tree"][0]["sigma_translation_mm"]
    )


def test_a_failed_rig_gate_exits_1_naming_the_pair(rig2):
    result = invoke("rig", "solve-folders", *_sources(rig2), "--min-shared-views", "30")
    assert result.exit_code == 1
    assert "gate rig-connected FAIL" in result.output and "CAM0-CAM1 shares 8 view(s)" in result.output


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--source", "CAM0=/x"], "camera CAM0 is given twice"),
        (["--root", "CAM9"], "--root CAM9 is not one of the cameras"),
    ],
)
def test_usage_errors_exit_2(rig2, extra, message):
    result = invoke("rig", "solve-folders", *_sources(rig2), *extra)
    assert result.exit_code == 2
    assert message in result.output and "Traceback" not in result.output


@needs_datasets
def test_solve_folders_takes_a_glob_and_a_list_file_like_rig_capture(tmp_path):
    """opencv-left-right keeps both cameras in one folder: a glob per camera needs no copying."""
    right_list = tmp_path / "right.txt"
    right_list.write_text("".join(f"{p}\n" for p in sorted(LEFT_RIGHT.glob("right*.jpg"))))
    board = ["--cols", "9", "--rows", "6", "--square-mm", "1"]  # square size unknown: baselines in squares
    result = invoke(
        "--json",
        "rig",
        "solve-folders",
        "--source",
        f"L={LEFT_RIGHT / 'left*.jpg'}",
        "--source",
        f"R={right_list}",
        *board,
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert (
        doc["frames"] == 13
        and doc["unmatched"] == []
        and doc["images"] == {"L": {"accepted": 13}, "R": {"accepted": 13}}
    )
    assert doc["verdict"] == "pass" and doc["lint"] == []  # k1k2 fits these lenses: the default model passes
    left, right = split_pairs(LEFT_RIGHT, tmp_path / "split", "left*.jpg", "right*.jpg")
    folders = json.loads(
        invoke(
            "--json", "rig", "solve-folders", "--source", f"L={left}", "--source", f"R={right}", *board
        ).output
    )
    assert doc["pairs"][0]["baseline_mm"] == pytest.approx(folders["pairs"][0]["baseline_mm"], rel=1e-9)


def test_a_failed_verdict_exits_1_and_withholds_the_exports(rig2, tmp_path):
    """The rig lint the stored path applies, with the station's limits (here an impossible epipolar one)."""
    station = tmp_path / "station.yaml"
    station.write_text("lint:\n  epipolar_max_px_at_720: 0.001\n")
    out = tmp_path / "out"
    result = invoke(
        "--station-config", str(station), "rig", "solve-folders", *_sources(rig2), "--export-dir", str(out)
    )
    assert result.exit_code == 1, result.output
    text = " ".join(result.output.split())
    assert "verdict: fail" in text and "error epipolar: CAM0-CAM1: held-out epipolar RMS" in text
    assert "exports not written" in text and not out.exists()
    result = invoke(
        "--station-config",
        str(station),
        "--json",
        "rig",
        "solve-folders",
        *_sources(rig2),
        "--export-dir",
        str(out),
        "--allow-rejected",
    )
    assert result.exit_code == 1
    doc = json.loads(result.output)
    assert (
        doc["verdict"] == "fail"
        and [f["rule"] for f in doc["lint"]] == ["epipolar"]
        and len(doc["exports"]) == 6
    )
    stereo = (out / "stereo_CAM0_CAM1.yaml").read_text()
    assert (
        f"# calibctl rig not stored (rig solve-folders) rejected solution-sha256 {doc['solution_sha256']}"
        in stereo
    )
    linted = invoke(
        "--json", "lint", str(out / "stereo_CAM0_CAM1.yaml")
    )  # a rejected solve's file fails lint
    assert linted.exit_code == 1 and "status" in {
        f["rule"] for f in json.loads(linted.output)["results"][0]["findings"]
    }


@needs_datasets
def test_baka_stereo_is_a_verdict_exit_1_not_a_failure_to_run(tmp_path):
    """It exited 2 ("the rig solve diverged") as if the tool had failed; every third pair keeps it fast."""
    lists = {}
    for side in ("left", "right"):
        lists[side] = tmp_path / f"{side}.txt"
        lists[side].write_text("".join(f"{p}\n" for p in sorted((BAKA_STEREO / side).glob("*.jpg"))[2::3]))
    result = invoke(
        "rig",
        "solve-folders",
        "--source",
        f"L={lists['left']}",
        "--source",
        f"R={lists['right']}",
        "--cols",
        "7",
        "--rows",
        "10",
        "--square-mm",
        "23",
    )
    assert result.exit_code == 1, result.output
    text = " ".join(result.output.split())
    assert (
        "error rig-rigid: the rig's frames contradict each other, so the cameras were not rigid or not "
        "synchronised" in text
    )
    assert "L-R: per-frame baseline" in text and "the cameras must not move against each other" in text
    assert "Traceback" not in result.output


def test_solve_folders_names_the_camera_of_a_source_it_cannot_use(rig2, tmp_path):
    (tmp_path / "clip.avi").write_bytes(b"not a video")
    board = ["--cols", "9", "--rows", "6", "--square-mm", "25"]
    for source, message in (
        (f"{tmp_path}/right*.jpg", f"camera B: --source '{tmp_path}/right*.jpg' matches no image file"),
        (
            str(tmp_path / "clip.avi"),
            "camera B: cannot decode the video " + str(tmp_path / "clip.avi"),  # a video pairs by time
        ),
    ):
        result = invoke(
            "rig", "solve-folders", "--source", f"A={rig2 / 'CAM0'}", "--source", f"B={source}", *board
        )
        assert result.exit_code == 2, result.output
        assert message in " ".join(result.output.split()) and "Traceback" not in result.output


def test_synth_rig_writes_folders_and_truth(tmp_path):
    result = invoke("--json", "synth", str(tmp_path / "r"), "--rig", "3", "--views", "3", "--size", "320x240")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert doc["cameras"] == ["CAM0", "CAM1", "CAM2"] and doc["n_frames"] == 3
    truth = json.loads((tmp_path / "r" / "rig_truth.json").read_text())
    assert truth["root"] == "CAM0" and len(truth["frames"]) == 3
    for name, count in doc["photos_per_camera"].items():
        assert len(list((tmp_path / "r" / name).glob("*.png"))) == count


def test_synth_rig_refuses_five_cameras(tmp_path):
    result = invoke("synth", str(tmp_path / "r"), "--rig", "5")
    assert result.exit_code == 2 and "--rig takes 2 to 4 cameras" in result.output


def test_solve_folders_with_the_same_folder_twice_is_refused_before_detection(rig2):
    result = invoke("rig", "solve-folders", *_sources(rig2, rig2 / "CAM0"))
    assert result.exit_code == 1, result.output
    text = " ".join(result.output.split())
    assert (
        "rig solve-folders: the members are not distinct cameras: CAM0 and CAM1 hold 8 of the same files"
        in text
    )
    assert "Traceback" not in result.output


@needs_datasets
def test_the_real_left_folder_given_twice_as_a_copy_is_refused(tmp_path):
    """The issue's case: opencv-left-right's left photos for both cameras (once as a byte copy)."""
    left, _ = split_pairs(LEFT_RIGHT, tmp_path / "split", "left*.jpg", "right*.jpg")
    copy = tmp_path / "copy"
    copy.mkdir()
    for p in left.iterdir():
        (copy / p.name.replace("left", "right")).write_bytes(p.read_bytes())
    result = invoke(
        "rig",
        "solve-folders",
        "--source",
        f"L={left}",
        "--source",
        f"R={copy}",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square-mm",
        "25",
    )
    assert result.exit_code == 1, result.output
    assert "L and R hold" in result.output and "identical image(s)" in result.output


def test_a_baseline_under_the_floor_fails_the_identity_rule(rig2, monkeypatch):
    """(synth --rig --baseline-mm 0 still offsets the camera ~2 mm in depth, and the solve sees it at 3.9
    sigma: no renderer makes a zero baseline, so this rig's 75 mm is read against a 100 mm floor.)"""
    from calibctl.workflows.rig import rig_folders

    real = rig_folders.identity.zero_baselines
    monkeypatch.setattr(rig_folders.identity, "zero_baselines", lambda pairs: real(pairs, floor_mm=100.0))
    result = invoke("--json", "rig", "solve-folders", *_sources(rig2))
    assert result.exit_code == 1, result.output
    doc = json.loads(result.output)
    found = [f for f in doc["lint"] if f["rule"] == "rig-identity"]
    assert doc["verdict"] == "fail" and "below the 100 mm floor" in found[0]["message"], doc["lint"]
