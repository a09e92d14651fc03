"""`calibctl station` with the store away, `station status` and `station sync`: lines, JSON, exit codes."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from calibctl.store.spool import Spool
from tests.workflows.station.spool_setup import away, central_folder, unit_folders

RUNNER = CliRunner()


@pytest.fixture
def queued(tmp_path: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    """CAM-1 stored online (the board remembered), then CAM-2 and CAM-3 queued with the store away."""
    central = central_folder(tmp_path)
    db, spool = f"sqlite:///{central / 'calibctl.db'}", tmp_path / "spool.sqlite"
    shots = unit_folders(tmp_path_factory, tmp_path)
    first = station(
        db,
        "--board",
        "A17",
        "--source-template",
        f"{shots}/{{serial}}",
        "--spool",
        str(spool),
        input="CAM-1\n",
    )
    assert first.exit_code == 0, first.output
    with away(central):
        result = station(
            db,
            "--board",
            "A17",
            "--source-template",
            f"{shots}/{{serial}}",
            "--spool",
            str(spool),
            "--json",
            input="CAM-2\nCAM-3\n",
        )
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert [(d["serial"], d["status"], d["verdict"], d["spool_record"], d["version"]) for d in lines] == [
        ("CAM-2", "queued", "pass", 1, None),
        ("CAM-3", "queued", "pass", 2, None),
    ]
    assert (
        "queued as spool record 1" in lines[0]["message"]
        and "unable to open database file" in lines[0]["message"]
    )
    return db, spool


def station(db: str, *args: str, input: str | None = None):
    return RUNNER.invoke(app, ["--db", db, "station", *args], input=input, terminal_width=110)


def test_status_lists_the_queue_and_sync_stores_it_in_order(queued: tuple[str, Path]) -> None:
    db, spool = queued
    status = station(db, "status", "--spool", str(spool), "--station", "line-3")
    assert status.exit_code == 2 and "belongs to station" in status.output  # the spool is this host's station
    status = station(db, "status", "--spool", str(spool))
    assert status.exit_code == 0, status.output
    out = status.stdout.splitlines()
    assert out[0].startswith(f"spool {spool} (station ") and out[0].endswith(
        ": 2 queued, 0 synced, 0 set aside"
    )
    assert out[1].startswith("  #1 CAM-2 session ") and out[1].endswith(": accepted, 12 image(s)")
    done = station(db, "sync", "--spool", str(spool), "--json")
    assert done.exit_code == 0, done.output
    synced = [json.loads(line) for line in done.stdout.splitlines()]
    assert [(d["seq"], d["serial"], d["version"], d["active"], d["already"]) for d in synced] == [
        (1, "CAM-2", 1, True, False),
        (2, "CAM-3", 1, True, False),
    ]
    again = station(db, "sync", "--spool", str(spool))
    assert again.exit_code == 0 and again.stdout == "" and "0 unit(s) synced, 0 queued" in again.stderr
    listing = json.loads(station(db, "status", "--spool", str(spool), "--json").stdout)
    assert listing["queued"] == [] and listing["synced"] == 2 and listing["set_aside"] == []
    with Store.open(db) as store:
        assert store.serials() == ["CAM-1", "CAM-2", "CAM-3"] and len(store.list_sessions()) == 3


def test_a_sync_with_the_store_still_away_exits_2_and_keeps_the_queue(
    queued: tuple[str, Path], tmp_path: Path
) -> None:
    db, spool = queued
    with away(tmp_path / "central"):
        done = station(db, "sync", "--spool", str(spool))
    assert done.exit_code == 2
    assert "there is no calibctl database at" in done.output and "(0 synced, 2 still queued)" in done.output


def test_a_changed_record_makes_sync_exit_1_naming_it(queued: tuple[str, Path]) -> None:
    db, spool = queued
    with sqlite3.connect(spool) as conn:
        conn.execute("UPDATE units SET serial = 'CAM-9' WHERE seq = 2")
    status = station(db, "status", "--spool", str(spool))
    assert "#2 CAM-9" in status.stdout and "REFUSED: it does not match its sha256" in status.stdout
    assert "calibctl station set-aside 2 --reason TEXT" in status.stdout
    done = station(db, "sync", "--spool", str(spool))
    assert done.exit_code == 1
    assert "CAM-2: spool record 1 stored as v1 accepted, active" in done.stdout
    assert "spool record 2 (CAM-9" in done.output and "(1 synced, 1 still queued)" in done.output
    with Store.open(db) as store:
        assert store.serials() == ["CAM-1", "CAM-2"]


def test_another_store_a_missing_spool_and_a_held_lock_exit_2(
    queued: tuple[str, Path], tmp_path: Path
) -> None:
    db, spool = queued
    other = station(f"sqlite:///{tmp_path / 'other.db'}", "sync", "--spool", str(spool))
    assert other.exit_code == 2 and "queues units for the store" in other.output
    missing = station(db, "status", "--spool", str(tmp_path / "none.sqlite"))
    assert missing.exit_code == 2 and "there is no spool at" in missing.output
    assert not (tmp_path / "none.sqlite").exists()
    with (
        Spool.open(
            spool,
            station=json.loads(station(db, "status", "--spool", str(spool), "--json").stdout)["station"],
            store=f"sqlite:///{tmp_path / 'central' / 'calibctl.db'}",
        ) as held,
        held.sync_lock(),
    ):
        locked = station(db, "sync", "--spool", str(spool))
    assert locked.exit_code == 2 and "is syncing the spool" in locked.output
    with Store.open(db) as store:
        assert store.serials() == ["CAM-1"]


def test_station_without_its_options_names_them(queued: tuple[str, Path]) -> None:
    db, _ = queued
    bare = station(db)
    assert bare.exit_code == 2 and "needs --board and --source-template" in bare.output


def test_set_aside_a_changed_record_and_sync_stores_the_rest_and_refusals_exit_2(
    queued: tuple[str, Path],
) -> None:
    db, spool = queued
    with sqlite3.connect(spool) as conn:
        conn.execute("UPDATE units SET serial = 'CAM-9' WHERE seq = 1")
    blocked = station(db, "sync", "--spool", str(spool))
    assert blocked.exit_code == 1 and "(0 synced, 2 still queued)" in blocked.output
    assert "calibctl station set-aside 1 --reason TEXT" in blocked.output
    aside = station(
        db,
        "set-aside",
        "1",
        "--reason",
        "serial edited by hand",
        "--spool",
        str(spool),
        "--operator",
        "op-ana",
    )
    assert aside.exit_code == 0, aside.output
    assert aside.stdout.startswith("CAM-9: spool record 1 (session ")
    assert aside.stdout.rstrip().endswith("set aside by op-ana: serial edited by hand")
    assert "with its 12 image(s), never synced; 1 record(s) still queued" in aside.stderr
    listed = station(db, "status", "--spool", str(spool)).stdout.splitlines()
    assert listed[0].endswith(": 1 queued, 0 synced, 1 set aside")
    assert listed[1].startswith("  #2 CAM-3 ") and listed[2].startswith("  #1 CAM-9 ")
    assert " SET ASIDE " in listed[2] and listed[2].endswith(
        "by op-ana: serial edited by hand (12 image(s) kept; never synced)"
    )
    done = station(db, "sync", "--spool", str(spool))
    assert done.exit_code == 0 and "CAM-3: spool record 2 stored as v1 accepted, active" in done.stdout
    listing = json.loads(station(db, "status", "--spool", str(spool), "--json").stdout)
    assert listing["queued"] == [] and listing["synced"] == 1
    assert [(a["seq"], a["serial"], a["operator"], a["reason"]) for a in listing["set_aside"]] == [
        (1, "CAM-9", "op-ana", "serial edited by hand")
    ]
    for args, message in (
        (["1", "--reason", "again"], "spool record 1 (CAM-9, session "),
        (["2", "--reason", "late"], "spool record 2 (CAM-3, session "),
        (["7", "--reason", "none"], "there is no spool record 7 in"),
        (["1", "--reason", " "], "setting a spool record aside needs a reason"),
    ):
        refused = station(db, "set-aside", *args, "--spool", str(spool))
        assert refused.exit_code == 2 and message in refused.output, refused.output
    assert "was set aside" in station(db, "set-aside", "1", "--reason", "x", "--spool", str(spool)).output
    with Store.open(db) as store:
        assert store.serials() == ["CAM-1", "CAM-3"]


def test_set_aside_json_and_a_station_with_a_key_refuses_a_spool_queued_without_one(
    queued: tuple[str, Path], tmp_path: Path
) -> None:
    db, spool = queued
    key = tmp_path / "station.key"
    assert RUNNER.invoke(app, ["keys", "init", "--key", str(key)]).exit_code == 0
    env = {"CALIBCTL_SIGNING_KEY": str(key)}
    status = RUNNER.invoke(app, ["--db", db, "station", "status", "--spool", str(spool), "--json"], env=env)
    assert status.exit_code == 0, status.output
    assert [(q["seq"], q["intact"]) for q in json.loads(status.stdout)["queued"]] == [(1, False), (2, False)]
    assert json.loads(status.stdout)["queued"][0]["problem"].startswith(
        "is not signed, and this station signs"
    )
    refused = RUNNER.invoke(app, ["--db", db, "station", "sync", "--spool", str(spool)], env=env)
    assert refused.exit_code == 1
    assert "spool record 1 (CAM-2, session " in refused.output and ") is not signed" in refused.output
    assert "(0 synced, 2 still queued)" in refused.output
    aside = RUNNER.invoke(
        app,
        [
            "--db",
            db,
            "station",
            "set-aside",
            "1",
            "--reason",
            "queued before the key",
            "--spool",
            str(spool),
            "--json",
        ],
        env=env,
    )
    assert aside.exit_code == 0, aside.output
    assert {
        k: v
        for k, v in json.loads(aside.stdout).items()
        if k not in ("session_id", "queued_at", "set_aside_at", "operator")
    } == {"seq": 1, "serial": "CAM-2", "reason": "queued before the key", "images": 12, "still_queued": 1}
    with Store.open(db) as store:
        assert store.serials() == ["CAM-1"]


def test_a_record_deleted_from_the_spool_stops_the_sync_until_it_is_set_aside(
    queued: tuple[str, Path],
) -> None:
    db, spool = queued
    with sqlite3.connect(spool) as conn:
        conn.execute("DELETE FROM units WHERE seq = 1")
    status = station(db, "status", "--spool", str(spool))
    assert "#1 MISSING: the record was deleted from the spool" in status.stdout
    assert json.loads(station(db, "status", "--spool", str(spool), "--json").stdout)["missing"] == [1]
    blocked = station(db, "sync", "--spool", str(spool))
    assert blocked.exit_code == 1, blocked.output
    assert (
        "spool record 1 is missing from" in blocked.output and "(0 synced, 1 still queued)" in blocked.output
    )
    assert "calibctl station set-aside 1 --reason TEXT" in blocked.output
    with Store.open(db) as store:
        assert store.serials() == ["CAM-1"]
    aside = station(db, "set-aside", "1", "--reason", "unit lost with the spool", "--spool", str(spool))
    assert aside.exit_code == 0, aside.output
    listing = json.loads(station(db, "status", "--spool", str(spool), "--json").stdout)
    assert listing["missing"] == []
    assert [(a["seq"], a["serial"], a["reason"]) for a in listing["set_aside"]] == [
        (1, "?", "unit lost with the spool")
    ]
    done = station(db, "sync", "--spool", str(spool))
    assert done.exit_code == 0 and "CAM-3: spool record 2 stored as v1 accepted, active" in done.stdout


def test_the_newest_record_deleted_is_missing_too(queued: tuple[str, Path]) -> None:
    db, spool = queued
    with sqlite3.connect(spool) as conn:
        conn.execute("DELETE FROM units WHERE seq = 2")
    done = station(db, "sync", "--spool", str(spool))
    assert done.exit_code == 1, done.output
    assert (
        "CAM-2: spool record 1 stored as v1" in done.stdout
        and "spool record 2 is missing from" in done.output
    )
