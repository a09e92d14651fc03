"""`calibctl station` never echoes a scanned serial's control characters raw: they drive the terminal."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board

SCANNED = "CAM\x1b[2J\x1b]0;pwn\x07-1"  # clear screen, set the window title, bell


@pytest.fixture
def db(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return sqlite_url


@pytest.mark.parametrize("json_lines", [False, True])
def test_a_serial_with_escape_sequences_is_shown_escaped(db: str, tmp_path: Path, json_lines: bool) -> None:
    args = ["--db", db, "station", "--board", "A17", "--source-template", f"{tmp_path}/{{serial}}"]
    result = CliRunner().invoke(app, [*args, *(["--json"] if json_lines else [])], input=SCANNED + "\n")
    assert result.exit_code == 0, result.output
    assert "\x1b" not in result.output and "\x07" not in result.output
    text = json.loads(result.stdout)["message"] if json_lines else result.stdout
    assert "'CAM\\x1b[2J\\x1b]0;pwn\\x07-1' is not a serial: it holds control characters" in text
    if not json_lines:
        assert "check the scanner's prefix and suffix settings" in result.stdout
