"""Code run in child processes by the concurrency and crash tests (spawned: a fresh interpreter each)."""

from __future__ import annotations

import os
import signal
import sys
from typing import Any

from sqlalchemy import Engine, event

from calibctl.store.repository import Store
from tests.artifacts.factories import calibration


def write_artifacts(url: str, serial: str, count: int, worker: int, barrier: Any, results: Any) -> None:
    """Wait until every worker is ready, then open the (possibly brand-new) store and add ``count``
    activated artifacts for ``serial`` as fast as possible; report the versions received."""
    try:
        barrier.wait()
        versions = []
        with Store.open(url) as store:
            for i in range(count):
                art = calibration(serial=serial, fx=800.0 + worker + i / 100)
                stored = store.add_artifact(
                    art, activate=True, actor=f"w{worker}", station=f"st{worker}", reason="load"
                )
                versions.append(stored.version)
        results.put((worker, versions, None))
    except BaseException as exc:  # report, so the parent fails with the reason instead of hanging
        results.put((worker, [], f"{type(exc).__name__}: {exc}"))
        raise


def crash_after_insert(url: str, serial: str) -> None:
    """Add an artifact and SIGKILL this process after its INSERT has run but before COMMIT.

    The hook is a monkeypatch living here, in the test's child process: SQLAlchemy events on the
    Engine class watch for the artifact INSERT and kill the process when the commit is attempted.
    """
    inserted = False

    def watch(conn: Any, cursor: Any, statement: str, *args: Any) -> None:
        nonlocal inserted
        if statement.lstrip().upper().startswith("INSERT INTO CALIBRATION_ARTIFACTS"):
            inserted = True

    def die_before_commit(conn: Any) -> None:
        if inserted:
            sys.stdout.flush()
            os.kill(os.getpid(), signal.SIGKILL)

    store = Store.open(url)
    event.listen(Engine, "before_cursor_execute", watch)
    event.listen(Engine, "commit", die_before_commit)
    store.add_artifact(
        calibration(serial=serial, fx=900.0), activate=True, actor="x", station="x", reason="crash"
    )
    raise SystemExit("the process should have been killed before the commit")


if __name__ == "__main__":
    crash_after_insert(sys.argv[1], sys.argv[2])


def write_sessions(url: str, count: int, worker: int, barrier: Any, results: Any) -> None:
    """Wait for every worker, then store ``count`` capture sessions, alternating two serials (so writers of
    one
    serial share its lock and writers of the other race them for the next id); report the session ids."""
    from tests.store.documents import capture_session

    try:
        barrier.wait()
        stored = []
        with Store.open(url) as store:
            for i in range(count):
                session_id = f"{worker:06x}{i:06x}"
                store.add_session(capture_session(session_id, serial=f"CAM-{i % 2}", minutes_after=i))
                stored.append(session_id)
        results.put((worker, stored, None))
    except BaseException as exc:  # report, so the parent fails with the reason instead of hanging
        results.put((worker, [], f"{type(exc).__name__}: {exc}"))
        raise
