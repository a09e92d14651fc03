"""`--image-circle` and the image circle found in the frames: capture, calibrate and solve of a circular
fisheye, a pinhole capture unchanged, and every bad circle."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from calibctl.workflows.lint.lint import facts_from_document
from calibctl.workflows.synth.synth import run_synth
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered

RUNNER = CliRunner()
SERIAL = "FE-0190"
RENDER_CIRCLE = (322.8, 237.4, 236.0)  # truth of the render: principal point and image circle, px
TOLERANCE_PX = 1.5


@pytest.fixture(scope="module")
def circular_190(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """190 deg circular fisheye, 640x480, seed 6: every gate passes with the circle (OpenCV 4.10 and 5.0);
    without it a corner cell, mostly outside the circle, is never reached."""
    out = tmp_path_factory.mktemp("fisheye") / "r190"
    run_synth(out, "good", seed=6, views=12, image_size=(640, 480), fisheye_fov_deg=190.0)
    return out


@pytest.fixture
def db(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return sqlite_url


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


def capture(db: str, source: Path, *extra: str):
    return invoke(db, "capture", "--serial", SERIAL, "--board", "A17", "--source", str(source), *extra)


def coverage(doc: dict) -> dict:
    return next(g for g in doc["session"]["gates"] if g["gate"] == "coverage")


def test_a_circular_fisheye_passes_coverage_over_the_circle_found_in_its_frames(
    db: str, circular_190: Path
) -> None:
    result = capture(db, circular_190, "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    gate = coverage(doc)
    assert (
        doc["session"]["status"] == "accepted"
        and gate["passed"]
        and (gate["value"], gate["threshold"]) == (5, 5)
    )
    detail = gate["detail"]
    assert detail["image_circle_source"] == "detected"
    found = (detail["image_circle_cx_px"], detail["image_circle_cy_px"], detail["image_circle_radius_px"])
    assert all(abs(a - b) < TOLERANCE_PX for a, b in zip(found, RENDER_CIRCLE, strict=True))
    assert len(detail["cells_outside_circle"]) == 4


def test_a_given_circle_is_recorded_and_the_fisheye_calibration_lints_inside_it(
    db: str, circular_190: Path
) -> None:
    result = invoke(
        db,
        "calibrate",
        "--serial",
        SERIAL,
        "--board",
        "A17",
        "--source",
        str(circular_190),
        "--model",
        "fisheye",
        "--image-circle",
        "322.8,237.4,236",
        "--json",
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    gate = next(g for g in doc["calibration"]["gates"] if g["gate"] == "coverage")
    assert (
        gate["detail"]["image_circle_source"] == "given" and gate["detail"]["image_circle_radius_px"] == 236.0
    )
    lint = invoke(db, "lint", "--serial", SERIAL, "--json")
    assert lint.exit_code == 0, lint.output
    # lint reads the circle back from the stored artifact's coverage gate (the fold-over check stops there)
    assert facts_from_document(doc["calibration"], SERIAL).image_circle == (322.8, 237.4, 236.0)


def test_a_pinhole_capture_has_no_circle_and_the_nine_cells_as_before(db: str, tmp_path_factory) -> None:
    result = capture(db, rendered(tmp_path_factory, "good"), "--json")
    assert result.exit_code == 0, result.output
    gate = coverage(json.loads(result.stdout))
    assert gate["threshold"] == 9 and set(gate["detail"]) == {"missing_cells"}


@pytest.mark.parametrize(
    ("circle", "words"),
    [
        ("320,240", "--image-circle '320,240' is not CX,CY,R"),
        ("a,b,c", "is not CX,CY,R"),
        ("320,240,inf", "is not CX,CY,R"),
        ("320,240,-5", "the radius must be positive, got -5 px"),
        ("700,200,100", "centre (700, 200) px lies outside the 640x480 image"),
        ("320,240,10", "(centre (320, 240) px, radius 10 px) covers no cell of the 3x3 coverage grid"),
    ],
)
def test_a_bad_circle_exits_2_with_its_numbers_and_stores_no_session(
    db: str, circular_190: Path, circle, words
):
    result = capture(db, circular_190, "--image-circle", circle)
    assert result.exit_code == 2, result.output
    assert words in " ".join(result.output.split())
    assert "Traceback" not in result.output
    with Store.open(db) as store:
        assert store.list_sessions() == []


def test_a_board_that_never_enters_the_given_circle_exits_2(db: str, tmp_path_factory) -> None:
    # the centre scenario keeps the board in the middle; a circle around the top-left corner never sees it
    result = capture(db, rendered(tmp_path_factory, "centre"), "--image-circle", "0,0,200")
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.split())
    assert (
        "the board never enters the image circle" in text and "centre (0.0, 0.0) px, radius 200.0 px" in text
    )
    assert "px outside it" in text
    with Store.open(db) as store:
        assert store.list_sessions() == []


def test_solve_records_a_given_circle_and_refuses_one_outside_the_image(db: str, circular_190: Path) -> None:
    captured = capture(db, circular_190, "--json")
    session_id = json.loads(captured.stdout)["session"]["session_id"]
    bad = invoke(db, "solve", session_id, "--model", "fisheye", "--image-circle", "-50,240,200")
    assert bad.exit_code == 2 and "centre (-50, 240) px lies outside the 640x480 image" in " ".join(
        bad.output.split()
    )
    good = invoke(db, "solve", session_id, "--model", "fisheye", "--image-circle", "322,237,230", "--json")
    assert good.exit_code == 0, good.output
    gate = next(g for g in json.loads(good.stdout)["gates"] if g["gate"] == "coverage")
    assert (gate["detail"]["image_circle_radius_px"], gate["detail"]["image_circle_source"]) == (
        230.0,
        "given",
    )


def test_a_rig_takes_no_image_circle(db: str) -> None:
    for args in (("capture", "--rig", "R1", "--board", "A17", "--source", "A=x"), ("solve", "--rig", "R1")):
        result = invoke(db, *args, "--image-circle", "1,2,3")
        assert result.exit_code == 2 and "--image-circle applies to one camera, not to a rig" in result.output


def test_a_video_capture_checks_a_given_circle_at_its_first_frame_and_records_it(
    db: str, tmp_path_factory
) -> None:
    video = rendered(tmp_path_factory, "video") / "video.avi"  # pinhole, 320x240
    bad = capture(db, video, "--image-circle", "400,120,50")
    assert bad.exit_code == 2 and "centre (400, 120) px lies outside the 320x240 image" in " ".join(
        bad.output.split()
    )
    good = capture(db, video, "--image-circle", "160,120,120", "--json")
    assert good.exit_code in (0, 1), good.output
    gate = coverage(json.loads(good.stdout))
    assert (
        gate["detail"]["image_circle_source"] == "given" and gate["detail"]["image_circle_radius_px"] == 120.0
    )
    assert gate["threshold"] == 5  # the four corner cells are less than half inside a 120 px circle


def test_the_gate_table_names_the_circle_the_cells_were_counted_in(db: str, circular_190: Path) -> None:
    result = capture(db, circular_190)
    assert result.exit_code == 0, result.output
    line = next(x for x in result.output.splitlines() if "gate coverage" in x)
    found = re.search(
        r"5 \(needs 5\) cells inside the image circle \(([\d.]+), ([\d.]+)\) r ([\d.]+) px, detected",
        " ".join(line.split()),
    )
    assert found is not None, line
    assert all(
        abs(float(v) - t) < 2 * TOLERANCE_PX for v, t in zip(found.groups(), RENDER_CIRCLE, strict=True)
    )
