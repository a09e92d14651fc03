"""The station's offline spool: a local SQLite file of units waiting for the central store.

When the central store cannot be reached, ``calibctl station`` keeps calibrating into this file: each
unit's capture session, its (unsealed, unversioned) calibration and the sha256 of its images, the image
files themselves in ``<spool>-images/`` (content-addressed, written durably before the record). The
central store gives each queued calibration its version when the spool is synced
(``workflows.station.sync``); a synced record is kept, marked with that version.

The file records the station it belongs to and the central store (``store_identity``) it queues for;
opening it as another station, or for another store, is refused. Every record carries a sha256 over
what it queues (and the spool's station and store), so a record edited, or copied in from another spool,
is found before it is synced. One process syncs a spool at a time (``sync_lock``, an ``flock``).

Standard-library ``sqlite3``: the spool is written while the station runs offline, and needs none of the
central store's schema, chains or migrations.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import sqlite3
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.artifacts.session import CaptureSession
from calibctl.errors import DatabaseError, FileSystemError, InputError, IntegrityError, UsageError
from calibctl.files import file_errors
from calibctl.store.codec import canonical_text
from calibctl.store.engine import display_url, parse_url, sqlite_path
from calibctl.store.images import image_file, write_durably

SPOOL_FORMAT = "calibctl-spool-1"
LOCK_WAIT_S = 10.0  # sqlite3's busy wait: the station queueing while a sync marks records
ORPHAN_GRACE_S = 3600.0  # image files written for a unit that was never queued (cancelled) go after an hour
_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS boards (ref TEXT PRIMARY KEY, name TEXT NOT NULL, revision INTEGER NOT NULL,
                                   document TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS units (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, serial TEXT NOT NULL, session_id TEXT NOT NULL UNIQUE,
    queued_at TEXT NOT NULL, session TEXT NOT NULL, artifact TEXT, session_stored INTEGER NOT NULL,
    images TEXT NOT NULL, record_sha256 TEXT NOT NULL, synced_at TEXT, version INTEGER);
"""
_FULL_HINT = ("free space on the spool's disk (or pass --spool on another disk), then scan the serial again: "
              "the unit's pictures are still where they arrived")


def store_identity(db_url: str) -> str:
    """The central store a spool belongs to: its URL without the password, a SQLite file by its absolute path."""
    url = parse_url(db_url)
    path = sqlite_path(url)
    if path is not None:
        return f"sqlite:///{path.resolve()}"
    return display_url(url)


@dataclass(frozen=True)
class SpoolRecord:
    """One queued unit. ``artifact`` is None for a capture the gates rejected (its session alone is queued);
    ``session_stored``: the session reached the store before it went away (only the calibration is queued)."""

    seq: int
    serial: str
    session_id: str
    queued_at: str
    session_text: str
    artifact_text: str | None
    session_stored: bool
    image_shas: tuple[str, ...]
    record_sha256: str
    synced_at: str | None
    version: int | None

    def verdict(self) -> str:
        if self.artifact_text is None:
            return "capture rejected"
        return str(json.loads(self.artifact_text)["status"])


class Spool:
    """An open spool file. ``Spool.open`` checks (or, new, records) its station and store."""

    def __init__(self, path: Path, conn: sqlite3.Connection, station: str, store: str) -> None:
        self.path, self._conn, self.station, self.store = path, conn, station, store
        self.image_dir = path.with_name(path.name + "-images")

    @classmethod
    def open(cls, path: Path, *, station: str, store: str, create: bool = True) -> Spool:
        if not path.exists() and not create:
            raise InputError(f"there is no spool at {path}", "pass the --spool the station ran with")
        with file_errors("open the spool", path.parent):
            path.parent.mkdir(parents=True, exist_ok=True)
        existed = path.exists() and path.stat().st_size > 0
        conn = None
        try:
            conn = sqlite3.connect(path, timeout=LOCK_WAIT_S, isolation_level=None)
            if existed and conn.execute("SELECT 1 FROM sqlite_master WHERE name = 'meta'").fetchone() is None:
                raise sqlite3.DatabaseError("file is not a database: it has no spool tables")
            conn.execute("PRAGMA journal_mode = WAL")
            conn.executescript(_SCHEMA)
            with _tx(conn, path):
                conn.execute("INSERT OR IGNORE INTO meta VALUES ('format', ?), ('station', ?), ('store', ?), "
                             "('created_at', ?)", (SPOOL_FORMAT, station, store, utc_now().isoformat()))
            meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
        except sqlite3.Error as exc:
            if conn is not None:
                conn.close()
            raise _spool_error(exc, path, "open") from exc
        spool = cls(path, conn, meta.get("station", ""), meta.get("store", ""))
        try:
            spool._check(meta, station, store)
        except BaseException:
            conn.close()
            raise
        return spool

    def _check(self, meta: dict[str, str], station: str, store: str) -> None:
        if meta.get("format") != SPOOL_FORMAT:
            raise InputError(f"{self.path} is not a calibctl spool (format {meta.get('format')!r})",
                             "pass the --spool file the station writes")
        if self.station != station:
            raise UsageError(f"the spool {self.path} belongs to station '{self.station}', not '{station}'; "
                             "nothing was queued or synced", f"run as that station (--station {self.station}) or "
                             "pass this station's own --spool")
        if self.store != store:
            raise UsageError(f"the spool {self.path} queues units for the store {self.store}, not {store}; "
                             "nothing was queued or synced", f"sync it with --db {self.store} (or pass the --spool "
                             "of this store)")

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> Spool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # writing -----------------------------------------------------------------------------------

    def put_images(self, images: Sequence[bytes]) -> list[str]:
        """Copy images in (durably, before any record names them); their sha256s, in order."""
        shas = [sha256_hex(data) for data in images]
        for sha, data in zip(shas, images, strict=True):
            path = image_file(self.image_dir, sha)
            if not (path.exists() and path.stat().st_size == len(data)):
                with _full_disk(self.path):
                    write_durably(path, data)
        return shas

    def queue(self, session: CaptureSession, artifact: CalibrationArtifact | None, *, session_stored: bool) -> int:
        """Queue one unit (its images are in already); its record number, the order it will be synced in."""
        images = tuple(sorted({v.image_sha256 for v in session.views if v.image_sha256} |
                              {o.sha256 for o in session.outcomes if o.sha256})) if not session_stored else ()
        missing = [sha for sha in images if not image_file(self.image_dir, sha).exists()]
        if missing:  # the capture copies every readable image in before the session exists
            raise FileSystemError(f"{len(missing)} image(s) of session {session.session_id} are not in the spool "
                                  f"({self.image_dir}); the unit was not queued", "scan the serial again")
        session_text = canonical_text(session)
        artifact_text = None if artifact is None else canonical_text(artifact)
        record = self._record_sha256(session.serial, session.session_id, session_text, artifact_text,
                                     session_stored, images)
        with _tx(self._conn, self.path):
            self._conn.execute("INSERT OR IGNORE INTO boards VALUES (?, ?, ?, ?)",
                               (session.board.ref, session.board.name, session.board.revision,
                                canonical_text(session.board)))
            cursor = self._conn.execute(
                "INSERT INTO units (serial, session_id, queued_at, session, artifact, session_stored, images, "
                "record_sha256) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (session.serial, session.session_id, utc_now().isoformat(), session_text, artifact_text,
                 int(session_stored), json.dumps(list(images)), record))
        assert cursor.lastrowid is not None
        return int(cursor.lastrowid)

    def remember_board(self, board: BoardRevision) -> None:
        """Keep a board revision the store served, for a station that later starts with the store away."""
        with _tx(self._conn, self.path):
            self._conn.execute("INSERT OR IGNORE INTO boards VALUES (?, ?, ?, ?)",
                               (board.ref, board.name, board.revision, canonical_text(board)))

    def mark_synced(self, seq: int, version: int | None) -> None:
        with _tx(self._conn, self.path):
            self._conn.execute("UPDATE units SET synced_at = ?, version = ? WHERE seq = ? AND synced_at IS NULL",
                               (utc_now().isoformat(), version, seq))

    def prune_images(self, now_s: float | None = None) -> int:
        """Delete image files no queued record needs (synced ones, or a cancelled unit's after an hour)."""
        needed, synced = self._image_shas(synced=False), self._image_shas(synced=True)
        cutoff = (time.time() if now_s is None else now_s) - ORPHAN_GRACE_S
        removed = 0
        for path in sorted(self.image_dir.glob("??/*")) if self.image_dir.is_dir() else []:
            if path.name in needed or (path.name not in synced and path.stat().st_mtime > cutoff):
                continue
            path.unlink(missing_ok=True)
            removed += 1
        return removed

    # reading -----------------------------------------------------------------------------------

    def counts(self) -> tuple[int, int]:
        """(queued, synced) records, without reading what they hold."""
        row = self._conn.execute("SELECT COUNT(*) - COUNT(synced_at), COUNT(synced_at) FROM units").fetchone()
        return int(row[0]), int(row[1])

    def _image_shas(self, *, synced: bool) -> set[str]:
        where = "synced_at IS NOT NULL" if synced else "synced_at IS NULL"
        return {sha for (images,) in self._conn.execute(f"SELECT images FROM units WHERE {where}")
                for sha in json.loads(images)}

    def records(self, *, pending_only: bool = False) -> list[SpoolRecord]:
        where = " WHERE synced_at IS NULL" if pending_only else ""
        try:
            rows = self._conn.execute(
                "SELECT seq, serial, session_id, queued_at, session, artifact, session_stored, images, record_sha256, "
                f"synced_at, version FROM units{where} ORDER BY seq").fetchall()
        except sqlite3.Error as exc:
            raise _spool_error(exc, self.path, "read") from exc
        return [SpoolRecord(int(r[0]), r[1], r[2], r[3], r[4], r[5], bool(r[6]), tuple(json.loads(r[7])), r[8], r[9],
                            r[10]) for r in rows]

    def board(self, name: str, revision: int | None) -> BoardRevision | None:
        """The newest remembered revision of ``name`` (or that revision); None when the spool never saw it."""
        query = "SELECT document FROM boards WHERE name = ?" + (" AND revision = ?" if revision is not None else "")
        params: tuple[object, ...] = (name,) if revision is None else (name, revision)
        row = self._conn.execute(query + " ORDER BY revision DESC LIMIT 1", params).fetchone()
        return None if row is None else BoardRevision.model_validate_json(row[0])

    def opened(self, record: SpoolRecord) -> tuple[CaptureSession, CalibrationArtifact | None]:
        """The record's session and calibration, after checking its sha256 (IntegrityError, exit 1)."""
        expected = self._record_sha256(record.serial, record.session_id, record.session_text, record.artifact_text,
                                       record.session_stored, record.image_shas)
        if expected != record.record_sha256:
            raise IntegrityError(
                f"spool record {record.seq} ({record.serial}, session {record.session_id}) does not match its sha256 "
                f"(recorded {record.record_sha256[:12]}, content hashes to {expected[:12]}): it was changed after it "
                f"was queued, or copied from another spool; it and the records after it were not synced",
                f"restore {self.path} from a backup, or recalibrate {record.serial}")
        try:
            session = CaptureSession.model_validate_json(record.session_text)
            artifact = (None if record.artifact_text is None
                        else CalibrationArtifact.model_validate_json(record.artifact_text))
        except ValueError as exc:  # pydantic's ValidationError: a record rewritten with its hash
            raise IntegrityError(f"spool record {record.seq} ({record.serial}) is not a session and calibration "
                                 f"calibctl wrote: {str(exc).splitlines()[0]}", f"restore {self.path} from a backup") from exc
        if session.session_id != record.session_id or session.serial != record.serial:
            raise IntegrityError(f"spool record {record.seq} names session {record.session_id} but holds "
                                 f"{session.session_id}", f"restore {self.path} from a backup")
        return session, artifact

    def image_bytes(self, record: SpoolRecord, sha: str) -> bytes:
        """A queued image, checked against its sha256 (IntegrityError when missing or changed)."""
        path = image_file(self.image_dir, sha)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            data = None
        if data is None or sha256_hex(data) != sha:
            what = "is missing" if data is None else f"does not match its sha256 (it hashes to {sha256_hex(data)[:12]})"
            raise IntegrityError(f"image {sha[:12]} of spool record {record.seq} ({record.serial}) {what}: {path}; "
                                 "it and the records after it were not synced",
                                 f"put the original file back, or recalibrate {record.serial}")
        return data

    def _record_sha256(self, serial: str, session_id: str, session_text: str, artifact_text: str | None,
                       session_stored: bool, images: Sequence[str]) -> str:
        parts = [SPOOL_FORMAT, self.station, self.store, serial, session_id, session_text, artifact_text or "",
                 str(int(session_stored)), ",".join(images)]
        return sha256_hex("\n".join(parts).encode("utf-8"))

    # one syncer at a time -------------------------------------------------------------------------

    @contextmanager
    def sync_lock(self) -> Iterator[None]:
        """Hold the spool's sync lock; refused at once (DatabaseError, exit 2) while another process holds it."""
        lock_path = self.path.with_name(self.path.name + ".sync-lock")
        with file_errors("open the spool's lock file", lock_path):
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise
                holder = os.pread(fd, 64, 0).decode("ascii", "replace").strip() or "?"
                raise DatabaseError(f"another process (pid {holder}) is syncing the spool {self.path}; this one synced "
                                    "nothing", "let it finish (calibctl station status shows what is left)") from exc
            os.ftruncate(fd, 0)
            os.pwrite(fd, str(os.getpid()).encode("ascii"), 0)
            yield
        finally:
            os.close(fd)  # closing the descriptor releases the flock


def default_spool_path(station_file: str | None, db_url: str) -> Path:
    """``calibctl-spool.sqlite`` in the station's folder: the station file's, else the SQLite store's, else ``.``."""
    if station_file:
        return Path(station_file).resolve().parent / "calibctl-spool.sqlite"
    path = sqlite_path(parse_url(db_url))
    return (path.resolve().parent if path is not None else Path.cwd()) / "calibctl-spool.sqlite"


@contextmanager
def _tx(conn: sqlite3.Connection, path: Path) -> Iterator[None]:
    try:
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield
            conn.execute("COMMIT")
        finally:
            if conn.in_transaction:  # SQLite rolls back by itself on some errors (SQLITE_FULL)
                conn.execute("ROLLBACK")
    except sqlite3.Error as exc:
        raise _spool_error(exc, path, "write") from exc


@contextmanager
def _full_disk(path: Path) -> Iterator[None]:
    try:
        yield
    except FileSystemError as exc:
        raise FileSystemError(f"the spool {path} cannot take the unit: {exc.message}; the unit was not queued",
                              _FULL_HINT) from exc


def _spool_error(exc: sqlite3.Error, path: Path, action: str) -> FileSystemError | InputError:
    text = str(exc).lower()
    if "full" in text or "disk i/o" in text:
        return FileSystemError(f"the disk of the spool {path} is full ({exc}); nothing was written to it", _FULL_HINT)
    if "not a database" in text or "no such table" in text:
        return InputError(f"{path} is not a calibctl spool ({exc})", "pass the --spool file the station writes")
    return FileSystemError(f"cannot {action} the spool {path}: {exc}", "check the path and its disk")

