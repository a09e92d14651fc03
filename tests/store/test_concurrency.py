"""Several stations writing at once, a writer killed mid-transaction, an interrupted write, a locked file."""

from __future__ import annotations

import multiprocessing
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import psycopg
import pytest
from sqlalchemy import Engine, event
from sqlalchemy.engine import make_url

from calibctl.errors import DatabaseError
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store import workers

REPO_ROOT = Path(__file__).resolve().parents[2]
PROCESSES = 4
PER_PROCESS = 5
CHILD_REPORT_WAIT_S = 300  # a hang guard for a broken child, not a speed check
WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


def test_concurrent_processes_get_distinct_versions_and_lose_nothing(db_url: str):
    ctx = multiprocessing.get_context("spawn")
    barrier = ctx.Barrier(PROCESSES)
    results = ctx.Queue()
    procs = [
        ctx.Process(target=workers.write_artifacts, args=(db_url, "CAM-9", PER_PROCESS, w, barrier, results))
        for w in range(PROCESSES)
    ]
    for p in procs:
        p.start()
    reports = [results.get(timeout=CHILD_REPORT_WAIT_S) for _ in procs]
    for p in procs:
        p.join()
    errors = [err for _, _, err in reports if err]
    assert not errors, errors
    assert [p.exitcode for p in procs] == [0] * PROCESSES
    total = PROCESSES * PER_PROCESS
    got = sorted(v for _, versions, _ in reports for v in versions)
    assert got == list(range(1, total + 1))  # distinct, gap-free: nothing lost, nothing doubled
    for _, versions, _ in reports:
        assert versions == sorted(versions)
    with Store.open(db_url) as store:
        stored = store.list_artifacts("CAM-9")
        events = store.events("CAM-9")
        assert [a.version for a in stored] == list(range(1, total + 1))
        assert store.active_version("CAM-9") == total
        assert store.verify().problems == []
    # Activation events were serialised too: each one names the version active just before it.
    assert [e.previous_version for e in events] == [None] + [e.version for e in events[:-1]]


def test_a_writer_killed_before_commit_leaves_no_artifact_and_no_half_version(db_url: str):
    with Store.open(db_url) as store:
        store.add_artifact(calibration(serial="CAM-K"), activate=True, **WHO)
    done = subprocess.run(
        [sys.executable, "-m", "tests.store.workers", db_url, "CAM-K"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == -signal.SIGKILL, done.stderr
    with Store.open(db_url) as store:
        assert [a.version for a in store.list_artifacts("CAM-K")] == [1]
        assert [e.version for e in store.events("CAM-K")] == [1]
        assert store.active_version("CAM-K") == 1
        assert store.verify().problems == []
        assert store.add_artifact(calibration(serial="CAM-K"), activate=True, **WHO).version == 2


def test_an_interrupted_write_is_rolled_back(db_url: str):
    with Store.open(db_url) as store:
        store.add_artifact(calibration(serial="CAM-I"), activate=True, **WHO)

        def interrupt(conn):
            raise KeyboardInterrupt

        event.listen(Engine, "commit", interrupt)
        try:
            with pytest.raises(KeyboardInterrupt):
                store.add_artifact(calibration(serial="CAM-I"), activate=True, **WHO)
        finally:
            event.remove(Engine, "commit", interrupt)
        assert [a.version for a in store.list_artifacts("CAM-I")] == [1]
        assert len(store.events("CAM-I")) == 1
        assert store.add_artifact(calibration(serial="CAM-I"), activate=True, **WHO).version == 2


def test_a_locked_sqlite_database_waits_a_bounded_time_then_says_so(sqlite_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_DB_LOCK_TIMEOUT_S", "0.5")
    with Store.open(sqlite_url) as store:
        blocker = sqlite3.connect(make_url(sqlite_url).database, isolation_level=None)
        blocker.execute("BEGIN IMMEDIATE")  # another writer holds the write lock
        try:
            started = time.monotonic()
            with pytest.raises(
                DatabaseError, match=r"is locked by another writer; gave up after 0.5 s"
            ) as info:
                store.add_board(measured_board())
            waited_s = time.monotonic() - started
            assert info.value.exit_code == 2 and "CALIBCTL_DB_LOCK_TIMEOUT_S" in (info.value.hint or "")
            assert waited_s >= 0.45  # it did wait for the lock (busy_timeout), it did not fail at once
            assert store.list_boards() == []  # readers are not blocked by a writer (WAL)
        finally:
            blocker.rollback()
            blocker.close()
        assert store.add_board(measured_board()).revision == 1


@pytest.mark.postgres
def test_a_locked_postgresql_row_waits_a_bounded_time_then_says_so(pg_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_DB_LOCK_TIMEOUT_S", "0.5")
    with Store.open(pg_url) as store:
        store.add_artifact(calibration(serial="CAM-L"), activate=True, **WHO)
        with psycopg.connect(pg_url) as other:  # a transaction that holds the serial's counter row
            other.execute("SELECT * FROM version_counters WHERE key = 'CAM-L' FOR UPDATE")
            with pytest.raises(DatabaseError, match=r"is locked by another writer; gave up after 0.5 s"):
                store.add_artifact(calibration(serial="CAM-L"), activate=True, **WHO)
            assert store.add_artifact(calibration(serial="CAM-OTHER"), activate=True, **WHO).version == 1
            other.rollback()
        assert store.add_artifact(calibration(serial="CAM-L"), activate=True, **WHO).version == 2
