"""Engines for the two supported backends, and the one place database errors become calibctl errors.

SQLite (the default, one file per station) and PostgreSQL (one store shared by every station of a
factory) run the same code and the same migrations. Differences are handled here:

* URLs: ``postgresql://`` and ``postgres://`` mean psycopg 3 (``postgresql+psycopg://``); a bare path
  means a SQLite file. Anything else is refused.
* SQLite: WAL journal (readers never wait for a writer), foreign keys on, and a *bounded* wait for
  the write lock (``CALIBCTL_DB_LOCK_TIMEOUT_S``, default 60 s on SQLite). SQLite's busy handler retries
  the lock with sleeps growing to 100 ms, which is not fair: under 16 station writers plus 8 rollback
  processes on the 2-core bench machine a writer waited more than 10 s (the old default) for its turn
  8 times in one run; at 60 s none gave up (tests/store/test_mixed_load.py). SQLAlchemy emits the ``BEGIN``
  itself so that write transactions start with ``BEGIN IMMEDIATE``: writers queue up at the start of the
  transaction instead of failing half-way when a read lock cannot be upgraded.
* PostgreSQL: the same setting bounds row-lock waits (``lock_timeout``, default 10 s: row locks are
  per serial and queue fairly); connects give up after 10 s.
"""

from __future__ import annotations

import functools
import os
import re
import sqlite3
import urllib.parse
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, create_engine, event
from sqlalchemy import exc as sa_exc
from sqlalchemy.engine import URL, make_url

from calibctl.errors import DatabaseError, DatabaseUnreachableError, MissingExtraError, UsageError

LOCK_TIMEOUT_ENV = "CALIBCTL_DB_LOCK_TIMEOUT_S"
DEFAULT_LOCK_TIMEOUT_S = 10.0
DEFAULT_SQLITE_LOCK_TIMEOUT_S = 60.0
CONNECT_TIMEOUT_S = 10
LOCK_TIMEOUT_OPTION = "calibctl_lock_timeout_s"
WRITE_OPTION = "calibctl_write"
"""Execution option marking a connection whose transactions write (SQLite: ``BEGIN IMMEDIATE``)."""

_SERIALIZATION_SQLSTATES = {"40001", "40P01"}  # serialization_failure, deadlock_detected
_LOCK_SQLSTATES = {"55P03"}  # lock_not_available (lock_timeout expired)
_UNIQUE_SQLSTATE = "23505"


def normalise_url(url: str) -> str:
    """The SQLAlchemy URL for ``url``: psycopg 3 for PostgreSQL, a bare path is a SQLite file."""
    url = url.strip()
    if not url:
        raise UsageError("the database URL is empty", "pass --db URL or set CALIBCTL_DB")
    if "://" not in url:
        return f"sqlite:///{url}"
    scheme, rest = url.split("://", 1)
    if scheme in ("postgresql", "postgres"):
        return f"postgresql+psycopg://{rest}"
    if scheme in ("postgresql+psycopg", "sqlite", "sqlite+pysqlite"):
        return url
    raise UsageError(
        f"unsupported database URL scheme '{scheme}://'",
        "use sqlite:///PATH (one station) or postgresql://USER@HOST/DB (shared by a factory)",
    )


def parse_url(url: str) -> URL:
    try:
        return make_url(normalise_url(url))
    except sa_exc.ArgumentError as exc:
        raise UsageError(f"'{display_url(url)}' is not a database URL: {exc}") from exc


def display_url(url: str | URL) -> str:
    """``url`` with the password replaced by ``***`` (and no driver name); safe for messages and logs."""
    try:
        parsed = url if isinstance(url, URL) else make_url(normalise_url(url))
        shown = parsed.render_as_string(hide_password=True)
    except (sa_exc.ArgumentError, UsageError, ValueError):
        shown = re.sub(r"://([^:/@]*):[^@/]*@", r"://\1:***@", str(url))
    return shown.replace("postgresql+psycopg://", "postgresql://", 1)


def lock_timeout_s(env: Mapping[str, str] | None = None, *, backend: str = "postgresql") -> float:
    """How long a writer waits for another writer's lock before giving up (seconds)."""
    env = os.environ if env is None else env
    raw = env.get(LOCK_TIMEOUT_ENV)
    if raw is None or raw.strip() == "":
        return DEFAULT_SQLITE_LOCK_TIMEOUT_S if backend == "sqlite" else DEFAULT_LOCK_TIMEOUT_S
    try:
        value = float(raw)
    except ValueError:
        value = -1.0
    if not (0 < value <= 3600):
        raise UsageError(f"{LOCK_TIMEOUT_ENV}={raw!r} is not a number of seconds in (0, 3600]")
    return value


def sqlite_path(url: URL) -> Path | None:
    """The file behind a SQLite URL (None for in-memory databases and other backends)."""
    if url.get_backend_name() != "sqlite" or url.database in (None, "", ":memory:"):
        return None
    return Path(url.database)


def make_engine(url: str, *, lock_timeout: float | None = None) -> Engine:
    """An engine for ``url`` with calibctl's connection settings; does not connect yet."""
    parsed = parse_url(url)
    backend = parsed.get_backend_name()
    timeout_s = lock_timeout_s(backend=backend) if lock_timeout is None else lock_timeout
    if backend == "sqlite":
        path = sqlite_path(parsed)
        if path is not None and read_only_file(path):
            engine = create_engine(parsed, creator=functools.partial(_connect_read_only, path, timeout_s))
        else:
            engine = create_engine(parsed, connect_args={"timeout": timeout_s})
        _configure_sqlite(engine, timeout_s, in_memory=path is None)
    else:
        connect_args: dict[str, Any] = {
            "connect_timeout": CONNECT_TIMEOUT_S,
            "options": f"-c lock_timeout={int(timeout_s * 1000)}",
        }
        try:
            engine = create_engine(parsed, connect_args=connect_args)
        except ModuleNotFoundError as exc:  # psycopg is the optional calibctl[postgres]
            raise MissingExtraError(
                "postgres", f"the PostgreSQL store {display_url(parsed)}", exc.name
            ) from exc
    return engine.execution_options(**{LOCK_TIMEOUT_OPTION: timeout_s})


def read_only_file(path: Path) -> bool:
    """A SQLite file that exists but that this user cannot write, or whose folder it cannot write (SQLite
    needs the folder for its -wal and -shm files): such a store is opened read-only."""
    return path.is_file() and not (os.access(path, os.W_OK) and os.access(path.parent, os.W_OK))


def _connect_read_only(path: Path, timeout_s: float) -> sqlite3.Connection:
    """A read-only connection (``mode=ro``). With no -wal file beside it, nobody is writing (nobody can:
    the folder or file is read-only), so ``immutable=1`` lets SQLite read a WAL-mode file without
    creating its -shm (a plain ``mode=ro`` open of it fails "attempt to write a readonly database")."""
    wal = path.with_name(path.name + "-wal")
    uri = f"file:{urllib.parse.quote(str(path.resolve()))}?mode=ro" + ("" if wal.exists() else "&immutable=1")
    connection = sqlite3.connect(uri, uri=True, timeout=timeout_s, check_same_thread=False)
    connection.execute("PRAGMA query_only = ON")
    return connection


def _configure_sqlite(engine: Engine, timeout_s: float, *, in_memory: bool) -> None:
    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        # Take transaction control away from the sqlite3 module; _on_begin emits BEGIN itself.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute(f"PRAGMA busy_timeout = {int(timeout_s * 1000)}")
        cursor.execute("PRAGMA foreign_keys = ON")
        read_only = bool(cursor.execute("PRAGMA query_only").fetchone()[0])  # _connect_read_only's
        if not in_memory and not read_only:  # a read-only store keeps the journal mode its writer set
            cursor.execute("PRAGMA journal_mode = WAL")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn: Any) -> None:
        write = conn.get_execution_options().get(WRITE_OPTION, False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")


def sqlstate(exc: BaseException) -> str | None:
    return getattr(getattr(exc, "orig", None), "sqlstate", None)


def is_retryable(exc: BaseException) -> bool:
    """PostgreSQL serialization failure or deadlock: the transaction may simply be run again."""
    return sqlstate(exc) in _SERIALIZATION_SQLSTATES


def is_unique_violation(exc: BaseException) -> bool:
    if sqlstate(exc) == _UNIQUE_SQLSTATE:
        return True
    return "UNIQUE constraint failed" in str(getattr(exc, "orig", exc))


def _is_connect_failure(code: str | None) -> bool:
    """No server, no such database, authentication refused, or the server is shutting down."""
    return code is None or code[:2] in ("08", "28") or code in ("3D000", "57P01", "57P02", "57P03")


def _first_line(exc: BaseException, hide: str | None) -> str:
    text = str(getattr(exc, "orig", None) or exc).strip()
    line = text.splitlines()[0].strip() if text else type(exc).__name__
    if hide:
        line = line.replace(hide, "***")
    return line


def translate(exc: sa_exc.DBAPIError | sa_exc.ArgumentError, engine: Engine) -> DatabaseError:
    """A DatabaseError for a driver error: locked, unreachable or refused, naming the URL (no password)."""
    shown = display_url(engine.url)
    detail = _first_line(exc, engine.url.password if isinstance(engine.url.password, str) else None)
    timeout_s = engine.get_execution_options().get(LOCK_TIMEOUT_OPTION, DEFAULT_LOCK_TIMEOUT_S)
    lowered = detail.lower()
    if (
        "database is locked" in lowered
        or "database table is locked" in lowered
        or sqlstate(exc) in _LOCK_SQLSTATES
    ):
        return DatabaseError(
            f"the database {shown} is locked by another writer; gave up after {timeout_s:g} s",
            f"another calibctl is writing to it: retry, or allow a longer wait with {LOCK_TIMEOUT_ENV}",
        )
    if engine.url.get_backend_name() == "sqlite":
        if "unable to open database file" in lowered:
            return DatabaseUnreachableError(
                f"cannot open the SQLite database {shown}: unable to open database file",
                "check that its directory exists and is writable, or pass another --db",
            )
        if "file is not a database" in lowered:
            return DatabaseError(f"{shown} is not a SQLite database ({detail})", "pass the right --db")
        if "readonly database" in lowered or "query_only" in lowered:
            return DatabaseError(
                f"the store {shown} is read-only for this user; nothing was written",
                "read commands work on it; to write, run as a user who can write both the file "
                "and its folder (SQLite keeps its -wal and -shm files there)",
            )
        if "disk i/o error" in lowered:
            return DatabaseError(
                f"the store {shown} could not write to its disk (disk I/O error); this transaction "
                "was not stored",
                "the disk is most likely full (df -h); else check the device",
            )
        if "database or disk is full" in lowered:
            return DatabaseError(
                f"the disk of the store {shown} is full; this transaction was not stored",
                "free some space on that disk and run the command again (image files a failed "
                "capture left are removed by `calibctl prune` an hour later)",
            )
    elif isinstance(exc, sa_exc.OperationalError | sa_exc.InterfaceError) and _is_connect_failure(
        sqlstate(exc)
    ):
        return DatabaseUnreachableError(
            f"cannot connect to the database {shown}: {detail}",
            "check --db / CALIBCTL_DB and that the server is running and reachable",
        )
    return DatabaseError(f"the database {shown} refused the operation: {detail}")


def as_database_error(exc: BaseException, engine: Engine) -> DatabaseError | None:
    """The DatabaseError a driver failure means for the user, or None when it is not one (a bug)."""
    if isinstance(exc, sa_exc.OperationalError | sa_exc.InterfaceError):
        return translate(exc, engine)
    if (
        isinstance(exc, sa_exc.DatabaseError)
        and engine.url.get_backend_name() == "sqlite"
        and "file is not a database" in str(exc.orig)
    ):
        return translate(exc, engine)
    return None


@contextmanager
def database_errors(engine: Engine) -> Iterator[None]:
    """Turn driver-level failures (locked, unreachable, ...) into calibctl DatabaseErrors."""
    try:
        yield
    except sa_exc.DBAPIError as exc:
        mapped = as_database_error(exc, engine)
        if mapped is None:
            raise
        raise mapped from exc
