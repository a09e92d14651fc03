"""calibctl board add --inverted / --legacy: ChArUco variants registered like any board; old boards
unchanged."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.common import parse_document
from calibctl.cli.main import app
from calibctl.workflows.board.boards import board_spec

CHARUCO = ["--kind", "charuco", "--cols", "3", "--rows", "4", "--square-mm", "54", "--marker-mm", "40.5"]
MEASURED = ["--uncertainty-mm", "0.05", "--instrument", "calipers", "--measured-by", "qa",
            "--measured-on", "2026-12-01"]  # fmt: skip


@pytest.fixture
def run(sqlite_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_OPERATOR", "tester")
    runner = CliRunner()
    return lambda *args: runner.invoke(app, ["--db", sqlite_url, *args])


def test_an_inverted_legacy_board_is_registered_and_detected_as_declared(run):
    result = run("board", "add", "CALI", *CHARUCO, *MEASURED, "--dictionary", "DICT_4X4_1000", "--inverted",
                 "--legacy", "--json")  # fmt: skip
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["inverted"] is True and doc["legacy_pattern"] is True
    spec = board_spec(parse_document(BoardRevision, doc, "CALI"))
    assert spec.inverted and spec.legacy_pattern and spec.dictionary == "DICT_4X4_1000"
    shown = run("board", "show", "CALI")
    assert "inverted (white markers on black)" in shown.output and "legacy layout" in shown.output


def test_a_plain_board_document_has_no_variant_keys_so_old_hashes_hold(run):
    result = run("board", "add", "PLAIN", *CHARUCO, *MEASURED, "--dictionary", "DICT_4X4_50", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert "inverted" not in doc and "legacy_pattern" not in doc
    board = parse_document(BoardRevision, doc, "PLAIN")
    assert board.model_dump(mode="json") == doc  # re-serialised byte for byte: the same content


def test_a_variant_flag_on_a_chessboard_is_refused(run):
    result = run("board", "add", "CB", "--cols", "9", "--rows", "6", "--square-mm", "25", "--inverted")
    assert result.exit_code == 2
    assert "--inverted and --legacy apply to ChArUco boards only" in result.output


def test_a_new_revision_may_not_change_the_polarity(run):
    assert run("board", "add", "C2", *CHARUCO, "--dictionary", "DICT_4X4_50").exit_code == 0
    result = run("board", "add", "C2", *CHARUCO, "--dictionary", "DICT_4X4_50", "--inverted")
    assert result.exit_code == 2 and "inverted differ" in result.output
