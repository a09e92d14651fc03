"""What `calibctl solve` / `calibrate` say beyond the numbers: a folder holding both cameras of a stereo pair
is a verdict, not a blend; a removed corner is printed and kept in the artifact."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.datasets import LEFT_RIGHT, require_datasets
from tests.workflows.sessions import synthetic_capture

RUNNER = CliRunner()


def folder(tmp_path: Path, pattern: str) -> Path:
    require_datasets()
    out = tmp_path / "shots"
    out.mkdir()
    for path in sorted(LEFT_RIGHT.glob(pattern)):
        shutil.copy(path, out / path.name)
    return out


def calibrate(db: str, source: Path, serial: str):
    with Store.open(db) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return RUNNER.invoke(
        app,
        ["--db", db, "calibrate", "--serial", serial, "--board", "A17", "--source", str(source)],
        terminal_width=110,
    )


def test_left_and_right_in_one_folder_are_called_two_cameras(tmp_path: Path, sqlite_url: str) -> None:
    # The capture gate catches the blend while the operator still holds the board: nothing is solved.
    result = calibrate(sqlite_url, folder(tmp_path, "*.jpg"), "STEREO-MIX")
    assert result.exit_code == 1, result.output
    assert "one_camera" in result.stdout and "two cameras" in result.stdout
    assert "not solved: the capture gates failed" in result.stdout
    history = RUNNER.invoke(app, ["--db", sqlite_url, "history", "STEREO-MIX"])
    assert (
        history.exit_code == 2 and "no calibration is stored for 'STEREO-MIX'" in history.output
    )  # no calibration was made
    with Store.open(sqlite_url) as store:
        session = store.latest_session("STEREO-MIX", status=None)
        assert session.status == "rejected"
        # The same views solved anyway (a session accepted before the gate existed): the solve's own check
        # rejects the blend, and the verdict lives in the artifact, so lint finds it again in an exported
        # file.
        blended = session.model_copy(update={"session_id": session.session_id[::-1], "status": "accepted"})
        store.add_session(blended)
    solved = RUNNER.invoke(app, ["--db", sqlite_url, "solve", blended.session_id], terminal_width=110)
    assert solved.exit_code == 1, solved.output
    assert "one-camera" in solved.output and "two cameras" in solved.output and "rejected" in solved.output, (
        solved.output
    )
    with Store.open(sqlite_url) as store:
        art = store.get_artifact("STEREO-MIX", 1)
    assert art.status == "rejected" and art.camera_consistency is not None
    assert {n[:4] for n in art.camera_consistency.group_a} == {"left"}
    assert {n[:5] for n in art.camera_consistency.group_b} == {"right"}
    exported = tmp_path / "mix.json"
    exported.write_text(art.model_dump_json(), encoding="utf-8")
    lint = RUNNER.invoke(app, ["lint", str(exported), "--format", "json"])
    assert lint.exit_code == 1 and '"one-camera"' in lint.stdout


@pytest.mark.parametrize("camera", ["left", "right"])
def test_each_camera_alone_is_not(tmp_path: Path, sqlite_url: str, camera: str) -> None:
    result = calibrate(sqlite_url, folder(tmp_path, f"{camera}*.jpg"), "STEREO-" + camera.upper())
    assert "one-camera" not in result.stdout, result.output
    with Store.open(sqlite_url) as store:
        check = store.get_artifact("STEREO-" + camera.upper()).camera_consistency
    assert check is not None and not check.two_cameras_suspected


def test_solve_prints_the_corner_it_removed_and_show_repeats_it(sqlite_url: str) -> None:
    session = synthetic_capture(measured_board("A17", square_mm=25.0), serial="CAM-0042")
    views = list(session.views)
    bad = list(views[3].corners_px)
    bad[10] = (bad[10][0] + 15.0, bad[10][1])
    views[3] = views[3].model_copy(update={"corners_px": bad})
    with Store.open(sqlite_url) as store:
        board = store.add_board(session.board)
        store.add_session(session.model_copy(update={"views": views, "board": board}))
    solved = RUNNER.invoke(app, ["--db", sqlite_url, "solve", "--serial", "CAM-0042"], terminal_width=110)
    assert solved.exit_code == 0, solved.output
    assert "corners removed from the solve: 1: view03.png id 10 (15.0 px)" in solved.stdout
    shown = RUNNER.invoke(app, ["--db", sqlite_url, "show", "CAM-0042"], terminal_width=110)
    assert shown.exit_code == 0 and "corners removed from the solve: 1: view03.png id 10" in shown.stdout
