"""A new user's pass over the real sets (../shared/datasets): the inputs a user really gives, each with
its message and exit code."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.datasets import LEFT_RIGHT, needs_datasets

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
    """`ls /data/left*.jpg > list.txt` names every view ../../data/left01.jpg (relative to the list's folder)."""
    lefts = sorted(LEFT_RIGHT.glob("left*.jpg"))
    listing = tmp_path / "lists" / "left.txt"
    listing.parent.mkdir()
    listing.write_text("".join(f"{p}\n" for p in lefts), encoding="utf-8")
    r = invoke(db, "--json", "capture", "--serial", "L1", "--board", "A17", "--source", str(listing))
    assert r.exit_code == 0, r.output
    session = json.loads(r.stdout)["session"]
    assert [v["name"] for v in session["views"]] == [str(p) for p in lefts]
    assert not any(".." in o["name"] for o in session["outcomes"])
