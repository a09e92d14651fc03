"""The offline spool: units calibrated while the store is away are queued, then stored in order with versions
from the store; a sync killed half-way and run again loses and doubles nothing; changed records, another
station's or store's spool, a second syncer and a full disk are refused with nothing lost."""

from __future__ import annotations

import errno
import json
import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from calibctl.errors import (
    DatabaseError,
    DatabaseUnreachableError,
    FileSystemError,
    IntegrityError,
    UsageError,
)
from calibctl.files import os_error
from calibctl.store.repository import Store
from calibctl.store.spool import Spool
from calibctl.workflows.camera import solve as solve_workflow
from calibctl.workflows.station import station as station_module
from calibctl.workflows.station.station import ERROR, PASS, QUEUED, SYNCED
from calibctl.workflows.station.sync import open_spool, status, sync
from tests.workflows.station.spool_setup import away, queue_three, run


def test_units_during_an_outage_are_queued_then_stored_in_order_before_the_next_unit(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    with Spool.open(spool, station="line-3", store=f"sqlite:///{central / 'calibctl.db'}") as opened:
        queued = [r.session_id for r in opened.records(pending_only=True)]
    lines = run(settings, shots, ["CAM-3"], spool)  # the store is back: synced at the start of the next unit
    assert [(r.serial, r.status, r.version, r.spool_record) for r in lines] == [
        ("CAM-1", SYNCED, 2, 1),
        ("CAM-2", SYNCED, 1, 2),
        ("CAM-1", SYNCED, 3, 3),
        ("CAM-3", PASS, 1, None),
    ]
    with Store.open(settings.db_url) as store:
        cam1 = store.list_artifacts("CAM-1")
        assert [a.version for a in cam1] == [1, 2, 3]  # both offline calibrations, in order, none skipped
        assert [a.provenance.session_id for a in cam1[1:]] == [queued[0], queued[2]]
        assert store.active_version("CAM-1") == 3 and store.active_version("CAM-2") == 1
        assert len(store.list_sessions()) == 5  # one per unit, none twice
        for art in cam1[1:]:
            assert all(store.image_path(sha) is not None for sha in art.provenance.input_image_sha256)
        assert store.verify().problems == []
    with open_spool(settings, spool) as opened:
        found = status(opened)
        assert found.queued == [] and found.synced == 3
        assert not any(opened.image_dir.glob("??/*"))  # the spool's copies go once the store holds them


def test_a_station_started_with_the_store_away_uses_the_board_its_spool_remembers(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    never_online = tmp_path / "new-spool.sqlite"
    with away(central):
        lines = run(settings, shots, ["CAM-2"], never_online)
    assert [r.status for r in lines] == [ERROR]
    assert "board A17 is unknown offline" in lines[0].message and "never seen it" in lines[0].message
    queue_three(
        settings, shots, tmp_path / "spool.sqlite", central
    )  # the second offline run used the spool's board


def test_a_sync_killed_after_storing_a_record_and_run_again_stores_nothing_twice(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)

    def killed_at_record_2(record) -> None:
        if record.seq == 2:
            raise KeyboardInterrupt  # stored in the store, not yet marked synced: the worst place to die

    with open_spool(settings, spool) as opened:
        with pytest.raises(KeyboardInterrupt):
            sync(settings, opened, after_store=killed_at_record_2)
        assert [r.seq for r in opened.records(pending_only=True)] == [2, 3]
        again = sync(settings, opened)
    assert [(u.seq, u.serial, u.version, u.already) for u in again.synced] == [
        (2, "CAM-2", 1, True),
        (3, "CAM-1", 3, False),
    ]
    assert again.error is None and again.left == 0
    with Store.open(settings.db_url) as store:
        assert [a.version for a in store.list_artifacts("CAM-1")] == [1, 2, 3]
        assert [a.version for a in store.list_artifacts("CAM-2")] == [1]
        assert len(store.list_sessions()) == 4


def test_a_changed_record_stops_the_sync_there_and_keeps_it_and_the_rest_queued(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    with sqlite3.connect(spool) as conn:
        text = conn.execute("SELECT artifact FROM units WHERE seq = 2").fetchone()[0]
        doc = json.loads(text)
        doc["rms_px"] = 0.01  # a better number, typed in by hand
        conn.execute("UPDATE units SET artifact = ? WHERE seq = 2", (json.dumps(doc),))
    with open_spool(settings, spool) as opened:
        assert [q.intact for q in status(opened).queued] == [True, False, True]
        done = sync(settings, opened)
    assert [u.seq for u in done.synced] == [1]
    assert isinstance(done.error, IntegrityError) and done.left == 2
    assert "spool record 2 (CAM-2" in done.error.message and "does not match its sha256" in done.error.message
    with Store.open(settings.db_url) as store:
        assert store.serials() == ["CAM-1"] and [a.version for a in store.list_artifacts("CAM-1")] == [1, 2]


def test_a_changed_image_is_found_before_its_record_is_stored(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    with open_spool(settings, spool) as opened:
        record = opened.records(pending_only=True)[0]
        image = opened.image_dir / record.image_shas[0][:2] / record.image_shas[0]
        image.write_bytes(image.read_bytes()[:-10])
        done = sync(settings, opened)
    assert done.synced == [] and isinstance(done.error, IntegrityError) and done.left == 3
    assert f"image {record.image_shas[0][:12]} of spool record 1 (CAM-1) does not match" in done.error.message
    with Store.open(settings.db_url) as store:
        assert [a.version for a in store.list_artifacts("CAM-1")] == [1] and len(store.list_sessions()) == 1


def test_another_stations_or_another_stores_spool_is_refused_with_nothing_touched(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    before = spool.read_bytes()
    other_station = settings.model_copy(update={"station": "line-4"})
    with pytest.raises(UsageError, match="belongs to station 'line-3', not 'line-4'"):
        run(other_station, shots, ["CAM-3"], spool)
    other_store = settings.model_copy(update={"db_url": f"sqlite:///{tmp_path / 'other.db'}"})
    with pytest.raises(UsageError, match=r"queues units for the store sqlite:///.*central/calibctl.db, not"):
        open_spool(other_store, spool)
    assert spool.read_bytes() == before
    with open_spool(settings, spool) as opened:
        assert len(opened.records(pending_only=True)) == 3


def test_a_second_syncer_is_refused_while_one_holds_the_spool(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    with open_spool(settings, spool) as first, open_spool(settings, spool) as second, first.sync_lock():
        with pytest.raises(DatabaseError, match=r"another process \(pid \d+\) is syncing the spool"):
            sync(settings, second)
        lines = run(settings, shots, ["CAM-3"], spool)  # the station queues behind the queue it cannot sync
    assert [(r.serial, r.status, r.spool_record) for r in lines] == [("CAM-3", QUEUED, 4)]
    assert "is syncing the spool" in lines[0].message
    with Store.open(settings.db_url) as store:
        assert store.serials() == ["CAM-1"] and len(store.list_artifacts("CAM-1")) == 1


def test_a_full_spool_disk_is_a_line_naming_it_and_nothing_is_queued(
    settings, shots: Path, central: Path, tmp_path: Path, monkeypatch
) -> None:
    spool = tmp_path / "spool.sqlite"
    assert [r.status for r in run(settings, shots, ["CAM-1"], spool)] == [PASS]

    def no_space(path: Path, data: bytes) -> None:
        raise os_error(OSError(errno.ENOSPC, "No space left on device"), "write the image", path)

    monkeypatch.setattr("calibctl.store.spool.write_durably", no_space)
    with away(central):
        lines = run(settings, shots, ["CAM-2"], spool)
    assert [r.status for r in lines] == [ERROR]
    assert "cannot take the unit" in lines[0].message and "no space left on the device" in lines[0].message
    assert "scan the serial again" in (lines[0].hint or "")
    with open_spool(settings, spool) as opened:
        assert opened.records() == []


def test_a_full_spool_database_refuses_the_record_and_keeps_the_others(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    with open_spool(settings, spool) as opened:
        session, artifact = opened.opened(opened.records()[0])
        pages = opened._conn.execute("PRAGMA page_count").fetchone()[0]
        opened._conn.execute(f"PRAGMA max_page_count = {pages}")  # SQLite's own "database or disk is full"
        with pytest.raises(FileSystemError, match="is full"):
            opened.queue(
                session.model_copy(update={"session_id": "feedfacecafe"}), artifact, session_stored=False
            )
        assert [r.seq for r in opened.records()] == [1, 2, 3]


def test_the_store_lost_between_the_session_and_its_calibration_queues_the_calibration_alone(
    settings, shots: Path, central: Path, tmp_path: Path, monkeypatch
) -> None:
    spool = tmp_path / "spool.sqlite"
    real_solve = solve_workflow.solve
    calls: list[str] = []

    def solve_then_lose_the_store(settings_, request):
        calls.append(request.session_id)
        if len(calls) == 2:  # it committed, then the connection broke: did it store? the sync finds out
            real_solve(settings_, request)
        raise DatabaseUnreachableError("cannot connect to the database: server closed the connection")

    monkeypatch.setattr(station_module, "solve", solve_then_lose_the_store)
    lines = run(settings, shots, ["CAM-1", "CAM-2"], spool)
    # the store answers again before CAM-2: CAM-1's queued calibration is synced first
    assert [(r.serial, r.status, r.spool_record, r.version) for r in lines] == [
        ("CAM-1", QUEUED, 1, None),
        ("CAM-1", SYNCED, 1, 1),
        ("CAM-2", QUEUED, 2, None),
    ]
    with open_spool(settings, spool) as opened:
        assert [(r.session_stored, r.image_shas) for r in opened.records()] == [(True, ()), (True, ())]
        done = sync(settings, opened)
    assert [(u.serial, u.version, u.already) for u in done.synced] == [("CAM-2", 1, True)]
    with Store.open(settings.db_url) as store:
        assert len(store.list_sessions()) == 2
        assert [a.provenance.session_id for a in store.list_artifacts("CAM-1")] == [calls[0]]
        assert [a.version for a in store.list_artifacts("CAM-2")] == [1]


_SYNC_THEN_DIE = """
import os, signal, sys
from pathlib import Path
from calibctl.config import load_settings
from calibctl.store.spool import Spool
from calibctl.workflows.station.sync import open_spool, sync

db, spool, dies_at = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])
settings = load_settings(db=db, station="line-3", operator="op-ana", env={})
mark = Spool.mark_synced

def die_before_marking(self, seq, version):
    if seq == dies_at:  # stored in the store, not yet marked in the spool: SIGKILL, no cleanup of any kind
        os.kill(os.getpid(), signal.SIGKILL)
    mark(self, seq, version)

Spool.mark_synced = die_before_marking
with open_spool(settings, spool) as opened:
    sync(settings, opened)
"""


def test_a_sync_process_killed_with_sigkill_leaves_no_lock_and_the_next_sync_finishes_it(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    killed = subprocess.run(
        [sys.executable, "-c", _SYNC_THEN_DIE, settings.db_url, str(spool), "2"],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    with open_spool(settings, spool) as opened:
        assert [r.seq for r in opened.records(pending_only=True)] == [2, 3]
        done = sync(settings, opened)  # the dead process's flock went with it
    assert [(u.seq, u.version, u.already) for u in done.synced] == [(2, 1, True), (3, 3, False)]
    with Store.open(settings.db_url) as store:
        assert [a.version for a in store.list_artifacts("CAM-1")] == [1, 2, 3]
        assert [a.version for a in store.list_artifacts("CAM-2")] == [1] and len(store.list_sessions()) == 4
        assert store.verify().problems == []
