"""`calibctl station`: serials from stdin and from a file, JSON lines, exit codes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered

RUNNER = CliRunner()


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rendered(tmp_path_factory, "good")


@pytest.fixture
def db(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return sqlite_url


@pytest.fixture
def shots(tmp_path: Path, good: Path) -> Path:
    for serial in ("CAM-1", "CAM-2"):
        shutil.copytree(good, tmp_path / "shots" / serial, ignore=shutil.ignore_patterns("*.json"))
    return tmp_path / "shots"


def invoke(db: str, *args: str, input: str | None = None):
    return RUNNER.invoke(
        app, ["--db", db, "station", "--board", "A17", *args], input=input, terminal_width=110
    )


def test_stdin_serials_give_one_json_line_per_unit_and_exit_0(db: str, shots: Path) -> None:
    result = invoke(
        db, "--source-template", f"{shots}/{{serial}}", "--json", "--jobs", "2", input="CAM-1\nCAM-1\nCAM-2\n"
    )
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert [(d["serial"], d["status"], d["version"]) for d in lines] == [
        ("CAM-1", "pass", 1),
        ("CAM-1", "error", None),
        ("CAM-2", "pass", 1),
    ]
    assert "already calibrated in this run" in lines[1]["message"]


def test_a_serials_file_gives_human_lines(db: str, shots: Path, tmp_path: Path) -> None:
    serials = tmp_path / "lot.txt"
    serials.write_text("CAM-2\nCAM-7\n")
    result = invoke(db, "--source-template", f"{shots}/{{serial}}", "--serials", str(serials))
    assert result.exit_code == 0, result.output
    out = result.stdout.splitlines()
    assert out[0].startswith("CAM-2: PASS - calibration v1 accepted, RMS ")
    assert out[1].startswith(f"CAM-7: ERROR - no pictures for CAM-7: {shots}/CAM-7 does not exist (")
    assert out[2].startswith("  hint: put the unit's pictures there")


def test_a_template_without_serial_and_a_missing_serials_file_exit_2(
    db: str, shots: Path, tmp_path: Path
) -> None:
    no_slot = invoke(db, "--source-template", str(shots), input="CAM-1\n")
    assert no_slot.exit_code == 2 and "has no {serial}" in no_slot.output
    missing = invoke(db, "--source-template", f"{shots}/{{serial}}", "--serials", str(tmp_path / "none.txt"))
    assert missing.exit_code == 2 and "none.txt" in missing.output
    with Store.open(db) as store:
        assert store.list_sessions() == []


# --camera: each unit live from the station's camera
# -------------------------------------------------------------


def test_a_camera_station_gives_a_line_per_unit_and_progress_on_stderr(
    db: str, tmp_path_factory, monkeypatch
) -> None:
    from calibctl.workflows.camera import capture_sources as sources

    video = rendered(tmp_path_factory, "video") / "video.avi"
    monkeypatch.setattr(
        sources, "open_stream", lambda spec: sources.VideoFileSource(video)
    )  # the unit's camera
    result = invoke(db, "--camera", "/dev/video7", "--json", input="CAM-1\n")
    assert result.exit_code == 0, result.output
    (line,) = [json.loads(text) for text in result.stdout.splitlines()]
    assert (line["serial"], line["status"], line["version"], line["views"]) == ("CAM-1", "pass", 1, 8)
    assert "calibctl capture: " in result.stderr  # the live capture's progress, plain lines off a terminal


def test_a_missing_camera_is_an_error_line_and_the_station_ends_at_the_input_end(db: str) -> None:
    if Path("/dev/video987").exists():
        pytest.skip("/dev/video987 exists on this machine: a test never opens a real device")
    result = invoke(db, "--camera", "/dev/video987", input="CAM-1\n")
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith(
        "CAM-1: ERROR - cannot open camera /dev/video987: /dev/video987 does not exist"
    )
    assert "hint: plug the camera in" in result.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--camera", "."], "--camera . is not a camera"),
        (["--camera", "/dev/video7", "--source-template", "shots/{serial}"], "the station takes one source"),
        (["--source-template", "shots/{serial}", "--max-views", "5"], "--max-views and --duration say when"),
        (["--camera", "/dev/video7", "--duration", "-1"], "--duration must be a positive number of seconds"),
        (["--camera", "/dev/video7", "--watch", "--views", "3"], "--watch waits for pictures in a folder"),
    ],
    ids=["a-folder", "both-sources", "max-views-without-camera", "negative-duration", "watch"],
)
def test_a_camera_station_that_cannot_start_exits_2(db: str, args: list[str], message: str) -> None:
    result = invoke(db, *args, input="CAM-1\n")
    assert result.exit_code == 2 and message in result.output
