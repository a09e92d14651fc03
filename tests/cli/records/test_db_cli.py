"""calibctl db upgrade | current | verify: wiring, messages, exit codes and --json, on both backends."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.tamper import patch_stored_bytes

HEAD = "0016_chain_health_reports"
runner = CliRunner()


def db(url: str, *args: str):
    return runner.invoke(app, ["--db", url, "db", *args])


def test_current_on_a_missing_sqlite_file_reports_it_without_creating_it(sqlite_url: str, tmp_path: Path):
    result = db(sqlite_url, "current")
    assert result.exit_code == 0, result.output
    assert "no database yet; it is created at head on first use" in result.stdout
    assert f"head      {HEAD}" in result.stdout
    report = json.loads(
        runner.invoke(app, ["--db", sqlite_url, "--json", "db", "current"]).stdout
    )  # global --json
    assert (report["status"], report["current"], report["head"], report["up_to_date"]) == (
        "absent",
        None,
        HEAD,
        False,
    )
    assert not (tmp_path / "calibctl.db").exists()


def test_upgrade_creates_then_has_nothing_to_do(db_url: str):
    created = db(db_url, "upgrade")
    assert created.exit_code == 0, created.output
    assert f"created at {HEAD} (head)" in created.stdout
    again = db(db_url, "upgrade", "--json")
    assert again.exit_code == 0
    report = json.loads(again.stdout)
    assert (report["before"], report["after"], report["changed"]) == (HEAD, HEAD, False)
    assert report["url"].split("://")[0] == ("postgresql" if db_url.startswith("postgresql") else "sqlite")


def test_current_reports_revision_and_contents(db_url: str):
    with Store.open(db_url) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(), activate=True, actor="qa", station="st1", reason="solved")
    result = db(db_url, "current")
    assert result.exit_code == 0
    assert f"revision  {HEAD}" in result.stdout and "status    up to date" in result.stdout
    assert "holds     1 artifacts, 1 serials, 1 boards, 0 sessions, 1 events, 0 images" in result.stdout
    report = json.loads(db(db_url, "current", "--json").stdout)
    assert report["up_to_date"] is True and report["counts"]["artifacts"] == 1
    assert report["backend"] == ("postgresql" if db_url.startswith("postgresql") else "sqlite")


def test_verify_exits_0_when_intact_and_1_naming_each_mismatch(db_url: str):
    with Store.open(db_url) as store:
        store.add_artifact(
            calibration(serial="CAM-A"), activate=True, actor="qa", station="st1", reason="solved"
        )
        store.add_artifact(
            calibration(serial="CAM-B"), activate=True, actor="qa", station="st1", reason="solved"
        )
    clean = db(db_url, "verify", "--json")
    assert clean.exit_code == 0 and json.loads(clean.stdout)["ok"] is True
    stdev_b = '"serial":"CAM-B","status":"accepted","stdev":{"parameter_count":'
    patch_stored_bytes(db_url, "calibration_artifacts", stdev_b + "11", stdev_b + "12")
    result = db(db_url, "verify")
    assert result.exit_code == 1
    assert "PROBLEM CAM-B@1 does not match its recorded sha256" in result.stdout
    assert "PROBLEM CAM-B@1 was changed after it was written" in result.stdout
    assert "CAM-A" not in result.stdout.replace("PROBLEM CAM-B", "")
    assert "verified 2 artifacts" in result.stdout and "2 problem(s)" in result.stdout


def test_verify_of_a_missing_database_exits_2(sqlite_url: str):
    result = db(sqlite_url, "verify")
    assert result.exit_code == 2
    assert "Error: there is no calibctl database at sqlite:///" in result.stderr
    assert (
        "does not exist" in result.stderr
        and "Hint:" in result.stderr
        and "calibctl db upgrade" in result.stderr
    )


def test_db_commands_exit_2_when_the_server_is_unreachable():
    for command in ("current", "upgrade", "verify"):
        result = db("postgresql://postgres@127.0.0.1:1/calibctl", command)
        assert result.exit_code == 2, (command, result.output)
        assert (
            "Error: cannot connect to the database postgresql://postgres@127.0.0.1:1/calibctl"
            in result.stderr
        )


def test_a_bad_lock_timeout_setting_exits_2(sqlite_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_DB_LOCK_TIMEOUT_S", "ten")
    result = db(sqlite_url, "upgrade")
    assert result.exit_code == 2
    assert "CALIBCTL_DB_LOCK_TIMEOUT_S='ten' is not a number of seconds in (0, 3600]" in result.stderr
