"""The read commands' reads of a SQLite store through the standard library's ``sqlite3``.

Importing sqlalchemy and mapping the tables costs a read command about 0.3 s of CPU before it reads a
byte (benchmarks/results/startup.md). ``history``, ``show``, ``export`` and ``board list`` of a SQLite store
read here instead: the same rows in the same order, decoded and integrity-checked by the same ``codec``
functions as ``Store``'s reads. Only the plain path is served here. Anything else - not a plain
``sqlite:///FILE`` URL, a file that does not exist, a schema revision other than this calibctl's head,
an unknown serial or version, nothing active, any sqlite3 error - falls back to ``Store``, which gives
the errors and messages it always has. Nothing here writes (the connection is ``query_only``) or creates.
"""

from __future__ import annotations

import datetime as dt
import os
import re
import sqlite3
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Protocol, TypeVar

from calibctl.store import codec, migrate
from calibctl.store.unreadable import unreadable_datetime

if TYPE_CHECKING:
    from calibctl.artifacts.board import BoardRevision
    from calibctl.artifacts.calibration import CalibrationArtifact
    from calibctl.artifacts.check import CheckEvent
    from calibctl.artifacts.events import ActivationEvent
    from calibctl.signing import TrustedKeys

T = TypeVar("T")
_PLAIN_SQLITE = re.compile(r"^sqlite:///(?P<path>[^?#%]+)$")
_DATETIME_COLUMNS = ("created_at", "stored_at", "at")
LOCK_TIMEOUT_S = (
    60.0  # engine.DEFAULT_SQLITE_LOCK_TIMEOUT_S (a test keeps them equal); engine imports sqlalchemy
)
LOCK_TIMEOUT_ENV = "CALIBCTL_DB_LOCK_TIMEOUT_S"  # set: Store reads, applying (and checking) it


class Fallback(Exception):  # noqa: N818 - a signal, not an error: read through Store instead
    """This read is not served here; ``Store`` does it (and raises whatever error applies)."""


class StoreReads(Protocol):
    """The reads both ``Store`` and ``SqliteReader`` offer."""

    def list_artifacts(self, serial: str) -> list[CalibrationArtifact]: ...
    def active_version(self, serial: str) -> int | None: ...
    def events(self, serial: str) -> list[ActivationEvent]: ...
    def checks(self, serial: str) -> list[CheckEvent]: ...
    def get_artifact(self, serial: str, version: int | None = None) -> CalibrationArtifact: ...
    def list_boards(self) -> list[BoardRevision]: ...


def _utc(text: str | None) -> dt.datetime | None:
    """A datetime column as the store's UtcDateTime returns it (SQLite keeps naive UTC text)."""
    if text is None:
        return None
    try:
        return dt.datetime.fromisoformat(text).replace(tzinfo=dt.UTC)
    except (TypeError, ValueError) as exc:
        raise unreadable_datetime(text) from exc


def _decode_artifact(row: SimpleNamespace) -> CalibrationArtifact:
    """The integrity check ``Store.get_artifact`` / ``list_artifacts`` make - the record's chain hash over
    every column (``chain_hash``), then the columns against the document - on a ``SELECT *`` row: keep the two
    the same."""
    return codec.decode_artifact(row, by_chain=True)  # type: ignore[arg-type]


class SqliteReader:
    """Read-only reads of one SQLite store at this calibctl's schema head (see the module docstring)."""

    def __init__(self, conn: sqlite3.Connection, trusted: TrustedKeys | None = None) -> None:
        self._conn = conn
        self._trusted = trusted

    def _served(self, stream: str, row: SimpleNamespace | None) -> None:
        """With keys configured, the check ``Store._served`` makes (``served``, same SQL)."""
        if row is not None and self._trusted is not None:
            from calibctl.store import served  # signing and the chain specs: only with keys configured

            served.check(
                stream, row, lambda sql, params: [vars(r) for r in self._rows(sql, params)], self._trusted
            )

    def _rows(self, sql: str, *params: object) -> list[SimpleNamespace]:
        """``params``: positional values, or one dict of named ones."""
        cursor = self._conn.execute(
            sql, params[0] if len(params) == 1 and isinstance(params[0], dict) else params
        )
        names = [c[0] for c in cursor.description]
        rows = []
        for values in cursor.fetchall():
            row = SimpleNamespace(**dict(zip(names, values, strict=True)))
            for name in _DATETIME_COLUMNS:
                if name in names:
                    setattr(row, name, _utc(getattr(row, name)))
            rows.append(row)
        return rows

    def _statuses(self, serial: str) -> dict[int, str]:
        rows = self._rows(
            "SELECT version, status FROM calibration_artifacts WHERE serial = ? ORDER BY version", serial
        )
        if not rows:
            raise Fallback  # unknown serial: Store names the known ones
        return {int(r.version): str(r.status) for r in rows}

    def list_artifacts(self, serial: str) -> list[CalibrationArtifact]:
        self._statuses(serial)
        return [
            _decode_artifact(r)
            for r in self._rows(
                "SELECT * FROM calibration_artifacts WHERE serial = ? ORDER BY version", serial
            )
        ]

    def active_version(self, serial: str) -> int | None:
        rows = self._rows(
            "SELECT version FROM activation_events WHERE serial = ? ORDER BY id DESC LIMIT 1", serial
        )
        return int(rows[0].version) if rows else None

    def events(self, serial: str) -> list[ActivationEvent]:
        return [
            codec.decode_event(r)  # type: ignore[arg-type]
            for r in self._rows(
                "SELECT id, serial, version, previous_version, kind, actor, station, at, reason FROM "
                "activation_events "
                "WHERE serial = ? ORDER BY id",
                serial,
            )
        ]

    def checks(self, serial: str) -> list[CheckEvent]:
        return [
            codec.decode_check(r)  # type: ignore[arg-type]
            for r in self._rows(
                "SELECT check_id, serial, version, passed, payload, payload_sha256 FROM check_events "
                "WHERE serial = ? ORDER BY id",
                serial,
            )
        ]

    def get_artifact(self, serial: str, version: int | None = None) -> CalibrationArtifact:
        statuses = self._statuses(serial)
        wanted = self.active_version(serial) if version is None else version
        if wanted not in statuses or (version is None and statuses[wanted] != "accepted"):
            raise Fallback  # nothing active, an active version that is not accepted, an unknown version
        rows = self._rows(
            "SELECT * FROM calibration_artifacts WHERE serial = ? AND version = ?", serial, wanted
        )
        art = _decode_artifact(rows[0])
        self._served("artifact", rows[0])
        if version is None and self._trusted is not None:  # the event that makes it active is served too
            event = self._rows(
                "SELECT * FROM activation_events WHERE serial = ? ORDER BY id DESC LIMIT 1", serial
            )
            self._served("event", event[0])
        return art

    def list_boards(self) -> list[BoardRevision]:
        """``Store.list_boards``' checks on the same rows: each revision's chain hash and payload hash, and
        with keys its link and signature."""
        boards = []
        for r in self._rows("SELECT * FROM board_revisions ORDER BY name, revision"):
            boards.append(codec.decode_board(r, by_chain=True))  # type: ignore[arg-type]
            self._served("board", r)
        return boards


@contextmanager
def _open(url: str, trusted: TrustedKeys | None = None) -> Iterator[SqliteReader]:
    match = _PLAIN_SQLITE.match(url.strip())
    path = Path(match["path"]) if match else None
    if (
        path is None
        or str(path) == ":memory:"
        or not path.is_file()
        or os.environ.get(LOCK_TIMEOUT_ENV, "").strip()
    ):
        raise Fallback  # another backend or URL form, no file, a lock timeout to apply: Store does it
    # mode=rw never creates the file; as the last connection of a WAL store closing, it removes the -wal and
    # -shm files as the ORM's connection does (mode=ro would leave them). query_only: this connection never
    # writes.
    conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=rw", uri=True, timeout=LOCK_TIMEOUT_S)
    try:
        conn.execute("PRAGMA query_only = ON")
        revisions = [r[0] for r in conn.execute("SELECT version_num FROM alembic_version").fetchall()]
        if revisions != [migrate.head_revision()]:
            raise Fallback  # out of date, unknown or several revisions: Store's messages
        conn.execute("BEGIN")  # one snapshot for every read of the command
        yield SqliteReader(conn, trusted)
    finally:
        conn.close()


def read(
    url: str,
    work: Callable[[StoreReads], T],
    store: Callable[[], AbstractContextManager[StoreReads]],
    trusted: TrustedKeys | None = None,
) -> T:
    """``work`` on the sqlite3 reader when it can serve it, else on ``store()`` (a ``Store``, opened with the
    same ``trusted`` keys: with keys, both check each served record's link and signature)."""
    try:
        with _open(url, trusted) as reader:
            return work(reader)
    except (Fallback, sqlite3.Error):
        pass
    with store() as full:
        return work(full)
