"""Read commands never create a store; `lint --all` lints every serial and never passes an empty store."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

runner = CliRunner()


def cli(url: str, *args: str):
    return runner.invoke(app, ["--db", url, *args])


@pytest.mark.parametrize(
    "args",
    [
        ("history", "CAM-0001"),
        ("show", "CAM-0001"),
        ("export", "CAM-0001", "--format", "ros"),
        ("lint", "--serial", "CAM-0001"),
        ("lint", "--all"),
        ("db", "verify"),
        ("board", "list"),
        # maintenance and writes to what must already be there: a typo is not a new store either
        ("prune",),
        ("prune", "--json"),
        ("rollback", "CAM-0001", "--to", "1", "--reason", "typo test"),
        ("solve", "--serial", "CAM-0001"),
    ],
)
def test_a_mistyped_sqlite_path_is_exit_2_and_creates_nothing(tmp_path: Path, args):
    typo = tmp_path / "typo.db"
    result = cli(f"sqlite:///{typo}", *args)
    assert result.exit_code == 2, result.output
    assert f"there is no calibctl database at sqlite:///{typo}" in result.stderr
    assert f"({typo} does not exist)" in result.stderr
    assert "Hint:" in result.stderr and "calibctl db upgrade" in result.stderr
    assert not typo.exists() and list(tmp_path.iterdir()) == []


def test_a_relative_path_is_named_in_full(tmp_path: Path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = cli("sqlite:///typo.db", "history", "CAM-0001")
    assert result.exit_code == 2 and f"({tmp_path / 'typo.db'} does not exist)" in result.stderr
    assert not (tmp_path / "typo.db").exists()


def test_write_commands_still_create_the_store(tmp_path: Path):
    board_db = tmp_path / "boards.db"
    added = cli(
        f"sqlite:///{board_db}", "board", "add", "A17", "--cols", "9", "--rows", "6", "--square-mm", "25"
    )
    assert added.exit_code == 0, added.output
    assert board_db.exists() and cli(f"sqlite:///{board_db}", "board", "list").exit_code == 0
    created = cli(f"sqlite:///{tmp_path / 'new.db'}", "db", "upgrade")
    assert created.exit_code == 0 and "created at" in created.stdout


def _store(url: str, *artifacts, activate=()) -> None:
    with Store.open(url) as store:
        for art in artifacts:
            store.add_artifact(
                art, activate=art.serial in activate, actor="qa", station="st1", reason="solved"
            )


def test_lint_all_reports_a_serial_without_accepted_version_as_a_finding(sqlite_url: str):
    _store(
        sqlite_url,
        calibration(serial="CAM-GOOD"),
        calibration(serial="CAM-BAD", status="rejected"),
        calibration(serial="CAM-BAD", version=2, status="rejected"),
        activate=("CAM-GOOD",),
    )
    result = cli(sqlite_url, "lint", "--all", "--json")
    assert result.exit_code == 1, result.output
    by_source = {r["source"]: r for r in json.loads(result.stdout)["results"]}
    assert by_source["CAM-GOOD@1"]["verdict"] == "pass"
    bad = by_source["CAM-BAD"]["findings"]
    assert [(f["rule"], f["severity"]) for f in bad] == [("no-active-version", "error")]
    assert "no accepted calibration (versions: 1 (rejected), 2 (rejected))" in bad[0]["message"]
    assert "calibctl calibrate --serial CAM-BAD" in bad[0]["fix"] and "rollback" not in bad[0]["fix"]


def test_lint_all_names_the_rollback_when_an_accepted_version_was_never_activated(sqlite_url: str):
    _store(sqlite_url, calibration(serial="CAM-IDLE"))
    result = cli(sqlite_url, "lint", "--all", "--json")
    assert result.exit_code == 1
    finding = json.loads(result.stdout)["results"][0]["findings"][0]
    assert finding["rule"] == "no-active-version" and "has no active version" in finding["message"]
    assert "calibctl rollback CAM-IDLE --to 1" in finding["fix"]
    text = cli(sqlite_url, "lint", "--all")
    assert text.exit_code == 1 and "CAM-IDLE" in text.stdout and "FAIL" in text.stdout


def test_lint_all_of_an_empty_store_is_exit_2_never_a_pass(sqlite_url: str):
    assert cli(sqlite_url, "db", "upgrade").exit_code == 0
    result = cli(sqlite_url, "lint", "--all", "--json")
    assert result.exit_code == 2
    assert (
        "nothing to lint: the store sqlite:///" in result.stderr and "holds no calibrations" in result.stderr
    )
    assert result.stdout == ""


@pytest.mark.postgres
def test_an_empty_postgresql_database_is_not_a_store_for_read_commands(pg_url: str):
    for args in (("history", "CAM-0001"), ("lint", "--all")):
        result = cli(pg_url, *args)
        assert result.exit_code == 2, result.output
        assert "there is no calibctl database at postgresql://" in result.stderr
        assert "(it has no calibctl tables)" in result.stderr
    assert (
        cli(pg_url, "db", "current").stdout.count("empty database") == 1
    )  # still empty: nothing was created
