"""Shared fixtures: an isolated environment, and fresh SQLite / PostgreSQL databases for store tests.

* ``sqlite_url``: a SQLite file in the test's tmp_path (it does not exist yet).
* ``pg_url``: a brand-new, uniquely named database on the local PostgreSQL server (created with
  psycopg in autocommit mode, dropped after the test). If the server is down it is started with
  ``pg_ctlcluster``; if it still cannot be reached the test *fails* -- it is never skipped silently.
* ``db_url``: both of the above (the PostgreSQL parameter carries the ``postgres`` marker).

Names are unique per test (uuid), so the suite is safe under ``pytest -n 2``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest

PG_ADMIN_URL = os.environ.get("CALIBCTL_TEST_PG_URL", "postgresql://postgres@127.0.0.1:5432/test")
"""A database on the server the tests may connect to as a superuser (to create/drop test databases)."""
PG_START_WAIT_S = 30.0


@pytest.fixture(autouse=True)
def _isolated_calibctl_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """A developer's CALIBCTL_* settings (database, station file, ...) never leak into a test."""
    for name in list(os.environ):
        if name.startswith("CALIBCTL_") and not name.startswith("CALIBCTL_TEST_"):
            monkeypatch.delenv(name)


@pytest.fixture(autouse=True)
def _no_remembered_checks() -> None:
    """core.capture.camera_split and core.intrinsics.model_select remember their last answers by the inputs' values; a test
    that patches their constants or solver must not be handed an answer another test computed."""
    for name in ("calibctl.core.capture.camera_split", "calibctl.core.intrinsics.model_select"):
        module = sys.modules.get(name)
        if module is not None:
            module._RECENT.clear()  # type: ignore[attr-defined]


@pytest.fixture
def sqlite_url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'calibctl.db'}"


def _pg_error() -> str | None:
    try:
        with psycopg.connect(PG_ADMIN_URL, connect_timeout=3) as conn:
            conn.execute("SELECT 1")
        return None
    except psycopg.Error as exc:
        return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def _start_local_cluster() -> str:
    versions = sorted(os.listdir("/etc/postgresql")) if os.path.isdir("/etc/postgresql") else []
    if not versions:
        return "no cluster under /etc/postgresql"
    done = subprocess.run(
        ["pg_ctlcluster", "--skip-systemctl-redirect", versions[-1], "main", "start"],
        capture_output=True,
        text=True,
        check=False,
    )
    return (done.stderr or done.stdout).strip()


@pytest.fixture(scope="session")
def pg_server() -> str:
    """The admin URL of a running local PostgreSQL (started on demand)."""
    error = _pg_error()
    if error is not None:
        start_output = _start_local_cluster()
        deadline = time.monotonic() + PG_START_WAIT_S
        while error is not None and time.monotonic() < deadline:
            time.sleep(0.5)
            error = _pg_error()
        if error is not None:
            pytest.fail(
                f"PostgreSQL at {PG_ADMIN_URL} is unreachable ({error}) and could not be started "
                f"({start_output or 'pg_ctlcluster said nothing'})"
            )
    return PG_ADMIN_URL


@pytest.fixture
def pg_url(pg_server: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """A fresh empty database; images of stores opened on it go to tmp_path."""
    name = f"calibctl_t_{uuid.uuid4().hex[:16]}"
    with psycopg.connect(pg_server, autocommit=True) as admin:
        admin.execute(f'CREATE DATABASE "{name}"')
    monkeypatch.setenv("CALIBCTL_IMAGE_DIR", str(tmp_path / "images"))
    base = pg_server.rsplit("/", 1)[0]
    try:
        yield f"{base}/{name}"
    finally:
        with psycopg.connect(pg_server, autocommit=True) as admin:
            admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def db_url(request: pytest.FixtureRequest) -> str:
    """The same test on a SQLite file and on a fresh PostgreSQL database."""
    return request.getfixturevalue("sqlite_url" if request.param == "sqlite" else "pg_url")


@pytest.fixture
def _require_datasets() -> None:
    """Used through tests.datasets.needs_datasets: skip locally / fail in CI without the real photos."""
    from tests.datasets import require_datasets

    require_datasets()


@pytest.fixture(autouse=True, scope="module")
def _no_warm_detection_pool_across_modules():
    """A module that warmed the detection process pool stops it when it ends: in another module, what a
    test patches in this process (detect_board, imdecode) must reach the (thread) workers."""
    yield
    if "calibctl.core.capture.worker_pool" in sys.modules:
        sys.modules["calibctl.core.capture.worker_pool"].shutdown_pool()
