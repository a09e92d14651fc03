"""Shared fixtures: an isolated environment, and fresh SQLite / PostgreSQL databases for store tests.

* ``sqlite_url``: a SQLite file in the test's tmp_path (it does not exist yet).
* ``pg_url``: a brand-new, uniquely named database on the local PostgreSQL server (created with
  psycopg in autocommit mode, dropped after the test). If the server is down it is started with
  ``pg_ctlcluster``; if it still cannot be reached the test *fails* -- it is never skipped silently.
* ``db_url``: both of the above (the PostgreSQL parameter carries the ``postgres`` marker).

A new SQLite store is migrated once per process: creating one (``Store.open``, ``db upgrade``) copies
that file instead of running the 15 migrations again (0.5-1 s each time); tests/store/test_migrations.py
runs them on every store it makes.

Names are unique per test (uuid), so the suite is safe under ``pytest -n 2``.
"""

from __future__ import annotations

import os
import shutil
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
    """core.capture.camera_split and core.intrinsics.model_select remember their last answers by the inputs'
    values; a test
    that patches their constants or solver must not be handed an answer another test computed."""
    for name in ("calibctl.core.capture.camera_split", "calibctl.core.intrinsics.model_select"):
        module = sys.modules.get(name)
        if module is not None:
            module._RECENT.clear()  # type: ignore[attr-defined]


_MIGRATED: dict[str, Path] = {}


@pytest.fixture(autouse=True)
def _new_sqlite_stores_copy_one_migrated_store(
    request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """``migrate.upgrade`` to head of a SQLite file that does not exist yet puts a copy of a store this
    process migrated once in its place (linked in whole, so a concurrent opener sees nothing or all of it);
    anything else (PostgreSQL, another target, a file already there, a missing folder) runs the migrations."""
    if request.node.path.name == "test_migrations.py":
        return
    from calibctl.store import migrate
    from calibctl.store.engine import make_engine, sqlite_path

    migrate_for_real = migrate.upgrade

    def upgrade(engine, target: str = "head"):
        path = sqlite_path(engine.url)
        if target != "head" or path is None or not path.parent.is_dir() or os.path.lexists(path):
            return migrate_for_real(engine, target)
        if "sqlite" not in _MIGRATED:
            migrated = tmp_path_factory.mktemp("migrated") / "calibctl.db"
            template = make_engine(f"sqlite:///{migrated}")
            try:
                migrate_for_real(template)
            finally:
                template.dispose()
            _MIGRATED["sqlite"] = migrated
        copy = path.with_name(f"{path.name}.{uuid.uuid4().hex}")
        shutil.copyfile(_MIGRATED["sqlite"], copy)
        try:
            os.link(copy, path)
        except FileExistsError:  # another opener made it meanwhile
            return migrate_for_real(engine, target)
        finally:
            copy.unlink()
        return None, migrate.head_revision()

    monkeypatch.setattr(migrate, "upgrade", upgrade)


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
