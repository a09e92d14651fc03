"""`calibctl station --watch`: the options, their usage errors, and the line's time after the last picture."""

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


@pytest.fixture
def db(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return sqlite_url


def invoke(db: str, *args: str, input: str | None = None):
    return RUNNER.invoke(
        app, ["--db", db, "station", "--board", "A17", *args], input=input, terminal_width=110
    )


def test_watch_lines_give_the_time_after_the_last_picture(
    db: str, tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
) -> None:
    good = rendered(tmp_path_factory, "good")
    shutil.copytree(good, tmp_path / "shots" / "CAM-1", ignore=shutil.ignore_patterns("*.json"))
    shutil.copytree(good, tmp_path / "shots" / "CAM-2", ignore=shutil.ignore_patterns("*.json"))
    (tmp_path / "shots" / "CAM-2" / "DONE").write_text("")
    views = str(len(list(good.glob("*.png"))))
    as_json = invoke(
        db,
        "--source-template",
        f"{tmp_path}/shots/{{serial}}",
        "--watch",
        "--views",
        views,
        "--settle-s",
        "0",
        "--json",
        "--jobs",
        "1",
        input="CAM-1\nCAM-1\n",
    )
    assert as_json.exit_code == 0, as_json.output
    line, twice = [json.loads(x) for x in as_json.stdout.splitlines()]
    assert line["status"] == "pass" and line["after_last_image_s"] >= 0
    assert (twice["status"], twice["after_last_image_s"]) == (
        "error",
        None,
    )  # a serial typed twice, as without --watch
    assert "already calibrated in this run" in twice["message"]
    human = invoke(
        db,
        "--source-template",
        f"{tmp_path}/shots/{{serial}}",
        "--watch",
        "--done-file",
        "DONE",
        "--jobs",
        "1",
        input="CAM-2\n",
    )
    assert human.exit_code == 0, human.output
    assert human.stdout.startswith("CAM-2: PASS - calibration v1 accepted, RMS ")
    assert " s after the last picture)" in human.stdout.splitlines()[0]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--views", "12"], "--views and --done-file say when a watched unit is complete; they need --watch"),
        (["--watch"], "--watch needs --views N or --done-file NAME"),
        (
            ["--watch", "--views", "12", "--unit-timeout-s", "-3"],
            "--unit-timeout-s must be a positive number",
        ),
        (
            ["--settle-s", "0"],
            "--settle-s and --unit-timeout-s say how long a watched unit's pictures are waited for; "
            "they need --watch",
        ),
        (["--unit-timeout-s", "30"], "they need --watch"),
    ],
)
def test_watch_options_that_cannot_work_exit_2_before_any_unit(
    db: str, tmp_path: Path, args: list[str], message: str
) -> None:
    result = invoke(db, "--source-template", f"{tmp_path}/{{serial}}", *args, input="CAM-1\n")
    assert result.exit_code == 2 and message in result.output, result.output
    assert "Traceback" not in result.output
    with Store.open(db) as store:
        assert store.list_sessions() == []
