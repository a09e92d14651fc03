"""A new user's pass over the real sets (../shared/datasets): the inputs a user really gives, each with
its message and exit code."""

from __future__ import annotations

import errno
import json
import re
import shutil
import tempfile
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.datasets import BAKA_STEREO, LEFT_RIGHT, needs_datasets

RUNNER = CliRunner()

pytestmark = needs_datasets


@pytest.fixture
def db(tmp_path: Path) -> str:
    url = f"sqlite:///{tmp_path / 'store.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return url


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=200)


def test_a_list_file_of_absolute_paths_names_the_views_as_written(db: str, tmp_path: Path) -> None:
    """`ls /data/left*.jpg > list.txt` names every view ../../data/left01.jpg (relative to the list's
    folder)."""
    lefts = sorted(LEFT_RIGHT.glob("left*.jpg"))
    listing = tmp_path / "lists" / "left.txt"
    listing.parent.mkdir()
    listing.write_text("".join(f"{p}\n" for p in lefts), encoding="utf-8")
    r = invoke(db, "--json", "capture", "--serial", "L1", "--board", "A17", "--source", str(listing))
    assert r.exit_code == 0, r.output
    session = json.loads(r.stdout)["session"]
    assert [v["name"] for v in session["views"]] == [str(p) for p in lefts]
    assert not any(".." in o["name"] for o in session["outcomes"])


def test_solve_report_into_a_folder_it_cannot_write_stores_nothing(
    db: str, tmp_path: Path, monkeypatch
) -> None:
    """The report folder was checked for existence only: a read-only one gave exit 2 *after* the new version
    was stored and activated (a rig pinned to the old one went stale without the user knowing)."""
    r = invoke(db, "capture", "--serial", "L1", "--board", "A17", "--source", str(LEFT_RIGHT / "left*.jpg"))
    assert r.exit_code == 0, r.output
    reports = tmp_path / "reports"
    reports.mkdir()

    def read_only(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)  # root ignores chmod: simulate the read-only folder
    r = invoke(db, "solve", "--serial", "L1", "--report", str(reports))
    assert r.exit_code == 2 and isinstance(r.exception, SystemExit)
    assert f"cannot write reports to {reports}: permission denied" in r.stderr
    monkeypatch.undo()
    r = invoke(db, "history", "L1")
    assert r.exit_code == 2 and "no calibration is stored for 'L1'" in r.stderr  # no version was stored


def test_the_tilt_hint_does_not_deny_the_directions_the_table_shows(db: str, tmp_path: Path) -> None:
    """left01-left09: the table lists views tilted bottom, top, left, top left, bottom right; the hint said
    "the tilted views so far all lean toward the bottom right and left"."""
    shots = tmp_path / "shots"
    shots.mkdir()
    for path in sorted(LEFT_RIGHT.glob("left0*.jpg")):
        shutil.copy(path, shots / path.name)
    r = invoke(db, "--json", "capture", "--serial", "L1", "--board", "A17", "--source", str(shots))
    # these 9 views predict the whole image within the projection gate's 5 px, so the session is
    # accepted and the failed tilt proxy is guidance (advisory); its hint must still be right
    assert r.exit_code == 0, r.output
    session = json.loads(r.stdout)["session"]
    tilt = next(g for g in session["gates"] if g["gate"] == "tilt")
    assert not tilt["passed"] and tilt["reason"] == "tilt.directions" and tilt["advisory"]
    assert next(g for g in session["gates"] if g["gate"] == "projection")["passed"]
    shown = {v["tilt_direction"] for v in session["views"] if 20.0 <= v["tilt_deg"] <= 45.0}
    assert len(shown) > len(tilt["detail"]["directions"])  # the case: more names than distinct directions
    assert "all lean toward" not in tilt["hint"]
    assert all(name in tilt["hint"] for name in shown), (shown, tilt["hint"])


def test_a_view_whose_tilt_cannot_be_read_says_why_in_the_table(tmp_path: Path) -> None:
    """baka-stereo left: an accepted view with a small board showed an empty tilt cell and no reason."""
    url = f"sqlite:///{tmp_path / 'store.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("B7", square_mm=23.0).model_copy(update={"cols": 7, "rows": 10}))
    r = invoke(url, "capture", "--serial", "BL", "--board", "B7", "--source", str(BAKA_STEREO / "left"))
    assert r.exit_code in (0, 1), r.output  # the verdict is the gates' business, not this test's
    session_id = re.search(r"session ([0-9a-f]{12}) (accepted|rejected)", r.stdout).group(1)  # type: ignore[union-attr]
    with Store.open(url) as store:
        session = store.get_session(session_id)
    unread = [v.name for v in session.views if v.tilt_deg is None]
    assert unread, "the case needs a view whose tilt is not read"
    rows = {line.split("│")[1].strip(): line for line in r.stdout.splitlines() if line.count("│") > 5}
    for name in unread:
        assert "not read" in rows[name] and "to read tilt" in rows[name], rows[name]


def test_rig_add_of_a_captured_but_uncalibrated_camera_says_what_is_missing(db: str) -> None:
    """baka-stereo's members are rejected at capture (coverage); `rig add` called them "unknown camera(s)"."""
    r = invoke(db, "capture", "--serial", "L1", "--board", "A17", "--source", str(LEFT_RIGHT / "left*.jpg"))
    assert r.exit_code == 0, r.output
    r = invoke(db, "rig", "add", "S1", "--camera", "L1", "--camera", "R1")
    assert r.exit_code == 2 and isinstance(r.exception, SystemExit)
    assert "camera(s) L1 have capture sessions but no calibration yet" in r.stderr
    assert "calibctl solve --serial" in r.stderr and "unknown camera" not in r.stderr
