"""calibctl board add --kind aprilgrid: Kalibr's target registered like any board (by options or its
target.yaml), its tag size measured with provenance, bad targets refused naming the fix, and a rendered
AprilGrid session calibrated end to end."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.common import parse_document
from calibctl.cli.main import app
from calibctl.workflows.board.boards import board_spec

runner = CliRunner()
GRID = [
    "--kind",
    "aprilgrid",
    "--tag-cols",
    "6",
    "--tag-rows",
    "6",
    "--tag-size-mm",
    "88",
    "--tag-spacing",
    "0.3",
]
MEASURED = ["--uncertainty-mm", "0.05", "--instrument", "calipers", "--measured-by", "qa",
            "--measured-on", "2026-12-01"]  # fmt: skip
KALIBR_TARGET = "target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n"


@pytest.fixture
def run(sqlite_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_OPERATOR", "tester")
    return lambda *args: runner.invoke(app, ["--db", sqlite_url, *args])


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    out = tmp_path_factory.mktemp("aprilgrid") / "shots"
    result = runner.invoke(app, ["synth", str(out), "--pattern", "aprilgrid", "--seed", "5"])
    assert result.exit_code == 0, result.output
    return out


def test_a_measured_aprilgrid_is_registered_with_its_span(run):
    # 6 tags and 5 gaps of 0.3 x 88 mm: 660 mm from outer tag corner to outer tag corner
    span = ["--span-mm", "660.1", "--span-uncertainty-mm", "0.2", "--span-instrument", "steel rule"]
    result = run("board", "add", "AG", *GRID, *MEASURED, *span, "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["kind"] == "aprilgrid" and (doc["cols"], doc["rows"]) == (12, 12)
    assert doc["tag_spacing"] == 0.3 and doc["dictionary"] == "DICT_APRILTAG_36h11"
    assert doc["measurement"]["status"] == "measured" and doc["measurement"]["square_size_m"] == 0.088
    spec = board_spec(parse_document(BoardRevision, doc, "AG"))
    assert spec.tags == (6, 6) and spec.n_corners == 144
    shown = run("board", "show", "AG")
    assert "aprilgrid 6x6 tags" in shown.output and "over 6 tags agrees" in shown.output


def test_a_span_that_contradicts_the_tag_size_is_refused(run):
    span = ["--span-mm", "686.4", "--span-uncertainty-mm", "0.2", "--span-instrument", "steel rule"]
    result = run("board", "add", "AG", *GRID, *MEASURED, *span)
    assert result.exit_code == 2 and "--tag-size-mm 88 x 7.5 (tags and gaps) = 660.00 mm" in result.output
    assert "AG@1" not in run("board", "list").output  # nothing stored


def test_kalibrs_target_yaml_gives_the_same_board(run, tmp_path):
    target = tmp_path / "target.yaml"
    target.write_text(KALIBR_TARGET)
    # as a Kalibr user brings it: the file says aprilgrid, so no --kind
    by_file = run("board", "add", "K1", "--from-kalibr", str(target), *MEASURED, "--json")
    by_flags = run("board", "add", "K2", *GRID, *MEASURED, "--json")
    assert by_file.exit_code == 0 and by_flags.exit_code == 0, by_file.output + by_flags.output
    keys = ("kind", "cols", "rows", "dictionary", "tag_spacing", "measurement")
    docs = [json.loads(r.stdout) for r in (by_file, by_flags)]
    assert [{k: d[k] for k in keys} for d in docs][0] == {k: docs[1][k] for k in keys}


def test_a_chessboard_document_has_no_tag_spacing_so_old_hashes_hold(run):
    result = run("board", "add", "CB", "--cols", "9", "--rows", "6", "--square-mm", "25", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert "tag_spacing" not in doc
    assert parse_document(BoardRevision, doc, "CB").model_dump(mode="json") == doc


@pytest.mark.parametrize(
    ("yaml_text", "says"),
    [
        (
            "target_type: 'checkerboard'\ntargetCols: 6\ntargetRows: 7\nrowSpacingMeters: 0.06\n",
            "not an aprilgrid",
        ),
        (KALIBR_TARGET.replace("0.088", "88"), "Kalibr's tagSize is in metres"),
        (KALIBR_TARGET.replace("tagSpacing: 0.3", "tagSpacing: -0.3"), "is not a ratio in (0, 1]"),
        (KALIBR_TARGET.replace("tagRows: 6\n", ""), "needs tagRows"),
        ("[1, 2]\n", "not a Kalibr target.yaml"),
    ],
)
def test_a_bad_kalibr_target_is_refused_naming_the_fix(run, tmp_path, yaml_text, says):
    target = tmp_path / "target.yaml"
    target.write_text(yaml_text)
    result = run("board", "add", "K", "--kind", "aprilgrid", "--from-kalibr", str(target))
    assert result.exit_code == 2 and says in result.output, result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize(
    ("args", "says"),
    [
        ([*GRID[:6], "--tag-size-mm=-88", *GRID[8:]], "--tag-size-mm -88 must be a positive length"),
        ([*GRID, "--family", "25h7"], "OpenCV has no AprilTag family '25h7'"),
        ([*GRID[:-1], "1.5"], "--tag-spacing is the gap over the tag edge"),
        (GRID[:-2], "an AprilGrid needs --tag-spacing"),
        ([*GRID, "--square-mm", "25"], "--square-mm describe a chessboard or ChArUco grid"),
        ([*GRID, "--marker-mm", "20"], "--marker-mm do not apply to an AprilGrid"),
        (["--cols", "9", "--rows", "6", "--square-mm", "25", "--tag-spacing", "0.3"], "add --kind aprilgrid"),
        (["--cols", "9", "--rows", "6"], "a chessboard needs --square-mm"),
        (["--kind", "chessboard", "--from-kalibr", "target.yaml"], "--from-kalibr describe an AprilGrid"),
    ],
)
def test_bad_aprilgrid_options_are_refused(run, args, says):
    result = run("board", "add", "B", *args)
    assert result.exit_code == 2 and says in result.output, result.output


def test_a_rendered_aprilgrid_session_calibrates(run, shots):
    truth = json.loads((shots / "truth.json").read_text())
    board = truth["board"]
    assert board["kind"] == "aprilgrid"
    tag_mm = str(board["square_size_m"] * 1000)
    added = run("board", "add", "AGS", "--kind", "aprilgrid", "--tag-cols", str(board["cols"] // 2),
                "--tag-rows", str(board["rows"] // 2), "--tag-size-mm", tag_mm,
                "--tag-spacing", str(board["tag_spacing"]), *MEASURED)  # fmt: skip
    assert added.exit_code == 0, added.output
    result = run("calibrate", "--serial", "AG-1", "--board", "AGS", "--source", str(shots), "--json")
    assert result.exit_code == 0, result.output
    art = json.loads(result.stdout)["calibration"]
    assert art["status"] == "accepted" and art["board"]["kind"] == "aprilgrid"
    K_true, K = truth["camera"]["K"], art["camera_matrix"]
    assert abs(K[0][0] - K_true[0][0]) < 4 * art["stdev"]["sigma"]["fx"]
    assert abs(K[0][2] - K_true[0][2]) < 1.5 and abs(K[1][2] - K_true[1][2]) < 1.5
    assert art["rms_px"] < 0.2


def test_a_grid_of_another_family_is_named_when_nothing_is_found(run, shots):
    added = run("board", "add", "AG16", *GRID, "--family", "16h5")
    assert added.exit_code == 0, added.output
    result = run("calibrate", "--serial", "AG-2", "--board", "AG16", "--source", str(shots))
    assert result.exit_code == 2, result.output
    assert (
        "no 6x6-tag AprilGrid (board AG16@1)" in result.output and "tag spacing and family" in result.output
    )


def test_a_fisheye_aprilgrid_render_is_refused(tmp_path):
    result = runner.invoke(app, ["synth", str(tmp_path / "fe"), "--pattern", "aprilgrid", "--fisheye", "150"])
    assert result.exit_code == 2 and "drop --fisheye or --pattern aprilgrid" in result.output
    assert not (tmp_path / "fe").exists()
