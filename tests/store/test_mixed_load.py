"""16 station writers and 8 rollback technicians on one store at once: nothing lost, nothing doubled,
nobody gave up on the lock at the default budget, and no rollback undid a version it had not seen."""

from __future__ import annotations

import multiprocessing

import pytest

from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.store import mixed_workers

SERIALS = ("CAM-M0", "CAM-M1", "CAM-M2", "CAM-M3")
WRITERS, TECHNICIANS, PER_PROCESS = 16, 8, 5
CHILD_REPORT_WAIT_S = 900  # a hang guard for a broken child, not a speed check


@pytest.mark.slow
def test_16_writers_and_8_rollbacks_lose_nothing_and_nobody_gives_up(db_url: str, monkeypatch):
    monkeypatch.delenv("CALIBCTL_DB_LOCK_TIMEOUT_S", raising=False)  # the default budget
    with Store.open(db_url) as store:
        for serial in SERIALS:
            for fx in (800.0, 801.0):
                store.add_artifact(
                    calibration(serial=serial, fx=fx), activate=True, actor="qa", station="s", reason="seed"
                )
    ctx = multiprocessing.get_context("spawn")
    barrier = ctx.Barrier(WRITERS + TECHNICIANS)
    results = ctx.Queue()
    procs = [
        ctx.Process(
            target=mixed_workers.station, args=(db_url, SERIALS[w % 4], PER_PROCESS, w, barrier, results)
        )
        for w in range(WRITERS)
    ]
    procs += [
        ctx.Process(
            target=mixed_workers.technician, args=(db_url, SERIALS[t % 4], PER_PROCESS, t, barrier, results)
        )
        for t in range(TECHNICIANS)
    ]
    for p in procs:
        p.start()
    reports = [results.get(timeout=CHILD_REPORT_WAIT_S) for _ in procs]
    for p in procs:
        p.join()
    assert [p.exitcode for p in procs] == [0] * len(procs)
    assert [r for r in reports if r[4]] == []  # no errors at all, so none gave up
    assert sum(r[3] for r in reports) == 0
    rollbacks_done = sum(r[2][0] for r in reports if r[0] == "rollback")
    assert (
        rollbacks_done == TECHNICIANS * PER_PROCESS
    )  # each decided again on a fresh read when refused stale
    with Store.open(db_url) as store:
        for serial in SERIALS:
            written = sorted(
                v for kind, s, versions, _, _ in reports if kind == "write" and s == serial for v in versions
            )
            per_serial = PER_PROCESS * WRITERS // len(SERIALS)
            assert written == list(range(3, 3 + per_serial))  # distinct, gap-free: nothing lost or doubled
            assert [a.version for a in store.list_artifacts(serial)] == list(range(1, 3 + per_serial))
            events = store.events(serial)
            # Every event names the version active just before it: no move was decided on a stale view.
            assert [e.previous_version for e in events[1:]] == [e.version for e in events[:-1]]
        assert store.verify().problems == []
