"""The station's offline spool: a local SQLite file of units waiting for the central store.

When the central store cannot be reached, ``calibctl station`` keeps calibrating into this file: each
unit's capture session, its (unsealed, unversioned) calibration and the sha256 of its images, the image
files themselves in ``<spool>-images/`` (content-addressed, written durably before the record). The
central store gives each queued calibration its version when the spool is synced
(``workflows.station.sync``); a synced record is kept, marked with that version.

The file records the station it belongs to and the central store (``store_identity``) it queues for;
opening it as another station, or for another store, is refused. Every record carries a sha256 over
what it queues (and the spool's station and store), so a record edited, or copied in from another spool,
is found before it is synced. That hash has no key: whoever can write the file can recompute it. So when
the station has a signing key, each record also carries the key's Ed25519 signature over its number and
sha256 (``_seal_message``), checked against the station's trusted keys before the record is synced
(keyed); without a key the sha256 alone is checked (unkeyed). One process syncs a spool at a time
(``sync_lock``, an ``flock``).

A record the sync refuses (changed, unsigned, a changed image) can be set aside by the operator
(``set_aside``): kept in the file with its images, the reason, the time and the operator, never synced, so
the records behind it are. Format 2 added those columns; a format-1 spool (written by the calibctl before)
is upgraded when it is opened, its records and their sha256s unchanged.

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
from typing import Any

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.artifacts.session import CaptureSession
from calibctl.errors import (
    AlreadyExistsError,
    DatabaseError,
    FileSystemError,
    InputError,
    IntegrityError,
    NotFoundError,
    UsageError,
)
from calibctl.files import file_errors
from calibctl.signing import Signer, TrustedKeys
from calibctl.store.codec import canonical_text
from calibctl.store.engine import display_url, parse_url, sqlite_path
from calibctl.store.images import image_file, write_durably

SPOOL_FORMAT = "calibctl-spool-2"  # 2: set-aside and signed records; an older calibctl refuses it (exit 2)
_FORMER_FORMATS = ("calibctl-spool-1",)  # upgraded on open
_RECORD_DOMAIN = (
    "calibctl-spool-1"  # the first line a record's sha256 covers: kept, so format-1 records still match
)
LOCK_WAIT_S = 10.0  # sqlite3's busy wait: the station queueing while a sync marks records
MAX_MISSING_LISTED = 100  # missing record numbers named at most (a forged counter could claim billions)
ORPHAN_GRACE_S = 3600.0  # image files written for a unit that was never queued (cancelled) go after an hour
_FORMAT_2_COLUMNS = (
    "set_aside_at",
    "set_aside_reason",
    "set_aside_by",
    "key_id",
    "signature",
)  # TEXT, NULL allowed
_SCHEMA = f"""
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS boards (ref TEXT PRIMARY KEY, name TEXT NOT NULL, revision INTEGER NOT NULL,
                                   document TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS units (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, serial TEXT NOT NULL, session_id TEXT NOT NULL UNIQUE,
    queued_at TEXT NOT NULL, session TEXT NOT NULL, artifact TEXT, session_stored INTEGER NOT NULL,
    images TEXT NOT NULL, record_sha256 TEXT NOT NULL, synced_at TEXT, version INTEGER,
    {", ".join(f"{column} TEXT" for column in _FORMAT_2_COLUMNS)});
CREATE TABLE IF NOT EXISTS missing_set_aside (seq INTEGER PRIMARY KEY, set_aside_at TEXT NOT NULL,
                                              set_aside_reason TEXT NOT NULL, set_aside_by TEXT NOT NULL);
"""
_UNITS_COLUMNS = (
    "seq, serial, session_id, queued_at, session, artifact, session_stored, images, record_sha256, "
    "synced_at, version, " + ", ".join(_FORMAT_2_COLUMNS)
)
_FULL_HINT = (
    "free space on the spool's disk (or pass --spool on another disk), then scan the serial again: "
    "the unit's pictures are still where they arrived"
)


def store_identity(db_url: str) -> str:
    """The central store a spool belongs to: its URL without the password, a SQLite file by its absolute
    path."""
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
    set_aside_at: str | None = None  # set aside by the operator: kept, never synced
    set_aside_reason: str | None = None
    set_aside_by: str | None = None
    key_id: str | None = (
        None  # the station key's signature over the record's number and sha256 (None: unkeyed)
    )
    signature: str | None = None

    def verdict(self) -> str:
        if self.artifact_text is None:
            return "capture rejected"
        return str(json.loads(self.artifact_text)["status"])


class Spool:
    """An open spool file. ``Spool.open`` checks (or, new, records) its station and store. ``signer``: the key
    records queued are signed with; ``trusted``: the keys records are checked against (None: unkeyed)."""

    def __init__(
        self,
        path: Path,
        conn: sqlite3.Connection,
        station: str,
        store: str,
        *,
        signer: Signer | None = None,
        trusted: TrustedKeys | None = None,
    ) -> None:
        self.path, self._conn, self.station, self.store = path, conn, station, store
        self.signer, self.trusted = signer, trusted
        self.image_dir = path.with_name(path.name + "-images")

    @classmethod
    def open(
        cls,
        path: Path,
        *,
        station: str,
        store: str,
        create: bool = True,
        signer: Signer | None = None,
        trusted: TrustedKeys | None = None,
    ) -> Spool:
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
                conn.execute(
                    "INSERT OR IGNORE INTO meta VALUES ('format', ?), ('station', ?), ('store', ?), "
                    "('created_at', ?)",
                    (SPOOL_FORMAT, station, store, utc_now().isoformat()),
                )
            meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
        except sqlite3.Error as exc:
            if conn is not None:
                conn.close()
            raise _spool_error(exc, path, "open") from exc
        spool = cls(
            path, conn, meta.get("station", ""), meta.get("store", ""), signer=signer, trusted=trusted
        )
        try:
            spool._check(meta, station, store)
            spool._upgrade(meta)
        except BaseException:
            conn.close()
            raise
        return spool

    def _check(self, meta: dict[str, str], station: str, store: str) -> None:
        if meta.get("format") not in (SPOOL_FORMAT, *_FORMER_FORMATS):
            raise InputError(
                f"{self.path} is not a calibctl spool (format {meta.get('format')!r})",
                "pass the --spool file the station writes",
            )
        if self.station != station:
            raise UsageError(
                f"the spool {self.path} belongs to station '{self.station}', not '{station}'; "
                "nothing was queued or synced",
                f"run as that station (--station {self.station}) or pass this station's own --spool",
            )
        if self.store != store:
            raise UsageError(
                f"the spool {self.path} queues units for the store {self.store}, not {store}; "
                "nothing was queued or synced",
                f"sync it with --db {self.store} (or pass the --spool of this store)",
            )

    def _upgrade(self, meta: dict[str, str]) -> None:
        """Format 1 -> 2: add the set-aside and signature columns (after the station and store were checked,
        so another station's spool is left as it is)."""
        if meta.get("format") == SPOOL_FORMAT:
            return
        with _tx(
            self._conn, self.path
        ):  # under the write lock: two processes opening an old spool upgrade it once
            have = {row[1] for row in self._conn.execute("PRAGMA table_info(units)")}
            for column in _FORMAT_2_COLUMNS:
                if column not in have:
                    self._conn.execute(f"ALTER TABLE units ADD COLUMN {column} TEXT")
            self._conn.execute("UPDATE meta SET value = ? WHERE key = 'format'", (SPOOL_FORMAT,))

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

    def queue(
        self, session: CaptureSession, artifact: CalibrationArtifact | None, *, session_stored: bool
    ) -> int:
        """Queue one unit (its images are in already); its record number, the order it will be synced in."""
        images = (
            tuple(
                sorted(
                    {v.image_sha256 for v in session.views if v.image_sha256}
                    | {o.sha256 for o in session.outcomes if o.sha256}
                )
            )
            if not session_stored
            else ()
        )
        missing = [sha for sha in images if not image_file(self.image_dir, sha).exists()]
        if missing:  # the capture copies every readable image in before the session exists
            raise FileSystemError(
                f"{len(missing)} image(s) of session {session.session_id} are not in the spool "
                f"({self.image_dir}); the unit was not queued",
                "scan the serial again",
            )
        session_text = canonical_text(session)
        artifact_text = None if artifact is None else canonical_text(artifact)
        record = self._record_sha256(
            session.serial, session.session_id, session_text, artifact_text, session_stored, images
        )
        with _tx(self._conn, self.path):
            self._conn.execute(
                "INSERT OR IGNORE INTO boards VALUES (?, ?, ?, ?)",
                (
                    session.board.ref,
                    session.board.name,
                    session.board.revision,
                    canonical_text(session.board),
                ),
            )
            cursor = self._conn.execute(
                "INSERT INTO units (serial, session_id, queued_at, session, artifact, session_stored, "
                "images, "
                "record_sha256) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    session.serial,
                    session.session_id,
                    utc_now().isoformat(),
                    session_text,
                    artifact_text,
                    int(session_stored),
                    json.dumps(list(images)),
                    record,
                ),
            )
            assert cursor.lastrowid is not None
            seq = int(cursor.lastrowid)
            if (
                self.signer is not None
            ):  # the number is the sync order: signed with it, in the same transaction
                self._conn.execute(
                    "UPDATE units SET key_id = ?, signature = ? WHERE seq = ?",
                    (self.signer.key_id, self.signer.sign(_seal_message(seq, record)), seq),
                )
        return seq

    def remember_board(self, board: BoardRevision) -> None:
        """Keep a board revision the store served, for a station that later starts with the store away."""
        with _tx(self._conn, self.path):
            self._conn.execute(
                "INSERT OR IGNORE INTO boards VALUES (?, ?, ?, ?)",
                (board.ref, board.name, board.revision, canonical_text(board)),
            )

    def set_aside(self, seq: int, *, reason: str, operator: str) -> SpoolRecord:
        """Set a queued record aside: kept with its images, never synced (call under ``sync_lock``, so no sync
        is storing it meanwhile). Refused (exit 2) for an unknown, a synced or an already set-aside record."""
        with _tx(self._conn, self.path):
            if seq in self.missing():
                return self._set_aside_missing(seq, reason, operator)
            record = self._record(seq)
            if record.synced_at is not None:
                stored = "a rejected capture session" if record.version is None else f"v{record.version}"
                raise UsageError(
                    f"spool record {seq} ({record.serial}, session {record.session_id}) was synced "
                    f"{record.synced_at[:19]} as {stored}; a stored record is not set aside",
                    f"to stop using the calibration, roll back: calibctl rollback {record.serial} "
                    "--to N --reason TEXT",
                )
            if record.set_aside_at is not None:
                raise AlreadyExistsError(
                    f"spool record {seq} ({record.serial}, session {record.session_id}) was set "
                    f"aside {record.set_aside_at[:19]} by {record.set_aside_by}: "
                    f"{record.set_aside_reason}; nothing changed",
                    "calibctl station status lists the records set aside",
                )
            self._conn.execute(
                "UPDATE units SET set_aside_at = ?, set_aside_reason = ?, set_aside_by = ? WHERE seq = ?",
                (utc_now().isoformat(), reason, operator, seq),
            )
            return self._record(seq)

    def _set_aside_missing(self, seq: int, reason: str, operator: str) -> SpoolRecord:
        """Record that the operator knows record ``seq`` is gone (inside ``set_aside``'s transaction): the
        records after it may sync. A stand-in record for the caller, with no session, calibration or
        images."""
        self._conn.execute(
            "INSERT INTO missing_set_aside VALUES (?, ?, ?, ?)",
            (seq, utc_now().isoformat(), reason, operator),
        )
        return next(r for r in self.missing_set_aside() if r.seq == seq)

    def missing_set_aside(self) -> list[SpoolRecord]:
        """The missing record numbers the operator set aside, as stand-in records (no session, calibration or
        images; serial ``?``), oldest first."""
        return [
            SpoolRecord(int(n), "?", "(deleted)", "", "", None, False, (), "", None, None, at, reason, by)
            for n, at, reason, by in self._conn.execute("SELECT * FROM missing_set_aside ORDER BY seq")
        ]

    def missing(self) -> list[int]:
        """The record numbers the spool handed out that it no longer holds (records are never deleted, so each
        is a record removed from the file), less those the operator set aside: 1 up to the highest number
        given, which SQLite's AUTOINCREMENT keeps even when the newest record is deleted."""
        (highest,) = self._conn.execute(
            "SELECT max(coalesce((SELECT seq FROM sqlite_sequence WHERE name = 'units'), 0), "
            "coalesce((SELECT max(seq) FROM units), 0))"
        ).fetchone()
        held = [
            int(r[0])
            for r in self._conn.execute(
                "SELECT seq FROM units UNION SELECT seq FROM missing_set_aside ORDER BY seq"
            )
        ]
        gone: list[int] = []
        for before, after in zip([0, *held], [*held, int(highest) + 1], strict=True):
            gone += range(before + 1, min(after, before + 1 + MAX_MISSING_LISTED - len(gone)))
        return gone

    def gap_before(self, record: SpoolRecord | None) -> IntegrityError | None:
        """The refusal of ``record`` (None: the end of the queue) when a record numbered before it is missing
        from the file (deleted: a unit that would be lost without a word, keyed or not), else None."""
        gone = [n for n in self.missing() if record is None or n < record.seq]
        if not gone:
            return None
        stopped = (
            f"record {record.seq} ({record.serial}) and the records after it were not synced"
            if record is not None
            else "the sync cannot tell whether it was stored"
        )
        return IntegrityError(
            f"spool record {gone[0]} is missing from {self.path} (records are numbered in the order they "
            f"were queued and never removed): it was deleted; {stopped}",
            f"restore {self.path} from a backup; or, knowing that unit is lost, set the number aside "
            f"(calibctl station set-aside {gone[0]} --reason TEXT) so the records after it sync",
        )

    def mark_synced(self, seq: int, version: int | None) -> None:
        with _tx(self._conn, self.path):
            self._conn.execute(
                "UPDATE units SET synced_at = ?, version = ? WHERE seq = ? AND synced_at IS NULL",
                (utc_now().isoformat(), version, seq),
            )

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

    def counts(self) -> tuple[int, int, int]:
        """(queued, synced, set aside) records, without reading what they hold."""
        row = self._conn.execute(
            "SELECT COUNT(*) - COUNT(synced_at) - COUNT(set_aside_at), COUNT(synced_at), "
            "COUNT(set_aside_at) FROM units"
        ).fetchone()
        return int(row[0]), int(row[1]), int(row[2])

    def _image_shas(self, *, synced: bool) -> set[str]:
        where = (
            "synced_at IS NOT NULL" if synced else "synced_at IS NULL"
        )  # a set-aside record's images are kept
        return {
            sha
            for (images,) in self._conn.execute(f"SELECT images FROM units WHERE {where}")
            for sha in json.loads(images)
        }

    def records(self, *, pending_only: bool = False, set_aside_only: bool = False) -> list[SpoolRecord]:
        """Every record, oldest first; ``pending_only``: those a sync stores (neither synced nor set
        aside)."""
        where = (
            " WHERE synced_at IS NULL AND set_aside_at IS NULL"
            if pending_only
            else " WHERE set_aside_at IS NOT NULL"
            if set_aside_only
            else ""
        )
        try:
            rows = self._conn.execute(f"SELECT {_UNITS_COLUMNS} FROM units{where} ORDER BY seq").fetchall()
        except sqlite3.Error as exc:
            raise _spool_error(exc, self.path, "read") from exc
        return [_record_of(row) for row in rows]

    def _record(self, seq: int) -> SpoolRecord:
        row = self._conn.execute(f"SELECT {_UNITS_COLUMNS} FROM units WHERE seq = ?", (seq,)).fetchone()
        if row is None:
            raise NotFoundError(
                f"there is no spool record {seq} in {self.path}",
                "calibctl station status lists the records by number (#N)",
            )
        return _record_of(row)

    def board(self, name: str, revision: int | None) -> BoardRevision | None:
        """The newest remembered revision of ``name`` (or that revision); None when the spool never saw it."""
        query = "SELECT document FROM boards WHERE name = ?" + (
            " AND revision = ?" if revision is not None else ""
        )
        params: tuple[object, ...] = (name,) if revision is None else (name, revision)
        row = self._conn.execute(query + " ORDER BY revision DESC LIMIT 1", params).fetchone()
        return None if row is None else BoardRevision.model_validate_json(row[0])

    def problem(self, record: SpoolRecord) -> str | None:
        """Why a sync refuses ``record`` (its sha256; keyed: its signature), or None."""
        expected = self._record_sha256(
            record.serial,
            record.session_id,
            record.session_text,
            record.artifact_text,
            record.session_stored,
            record.image_shas,
        )
        if expected != record.record_sha256:
            return (
                f"does not match its sha256 (recorded {record.record_sha256[:12]}, content hashes to "
                f"{expected[:12]}): it was changed after it was queued, or copied from another spool"
            )
        if self.trusted is None:
            return None  # unkeyed: a record's signature, if any, is not checked
        found = self.trusted.check(
            record.key_id, record.signature, _seal_message(record.seq, record.record_sha256)
        )
        if found == "is not signed":
            return (
                "is not signed, and this station signs its spool: it was queued by a station without the "
                "key, or "
                "rewritten with its signature taken off"
            )
        if found is not None and "does not match" in found:
            return f"{found}: it was rewritten (content and sha256, or its number) after it was queued"
        return (
            None
            if found is None
            else f"{found}: neither this station's key nor one in its trusted_keys folder"
        )

    def opened(self, record: SpoolRecord) -> tuple[CaptureSession, CalibrationArtifact | None]:
        """The record's session and calibration, after checking its sha256 and, keyed, its signature
        (IntegrityError, exit 1)."""
        problem = self.problem(record)
        if problem is not None:
            raise IntegrityError(
                f"spool record {record.seq} ({record.serial}, session {record.session_id}) {problem}; it "
                "and the "
                f"records after it were not synced",
                self._restore_hint(record),
            )
        try:
            session = CaptureSession.model_validate_json(record.session_text)
            artifact = (
                None
                if record.artifact_text is None
                else CalibrationArtifact.model_validate_json(record.artifact_text)
            )
        except ValueError as exc:  # pydantic's ValidationError: a record rewritten with its hash
            raise IntegrityError(
                f"spool record {record.seq} ({record.serial}) is not a session and calibration "
                f"calibctl wrote: {str(exc).splitlines()[0]}",
                self._restore_hint(record),
            ) from exc
        if session.session_id != record.session_id or session.serial != record.serial:
            raise IntegrityError(
                f"spool record {record.seq} names session {record.session_id} but holds {session.session_id}",
                self._restore_hint(record),
            )
        return session, artifact

    def _restore_hint(self, record: SpoolRecord, fix: str = "") -> str:
        return (
            f"{fix or f'restore {self.path} from a backup'}; or set it aside (calibctl station set-aside "
            f"{record.seq} --reason TEXT) so the records after it sync, and recalibrate {record.serial}"
        )

    def image_bytes(self, record: SpoolRecord, sha: str) -> bytes:
        """A queued image, checked against its sha256 (IntegrityError when missing or changed)."""
        path = image_file(self.image_dir, sha)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            data = None
        if data is None or sha256_hex(data) != sha:
            what = (
                "is missing"
                if data is None
                else f"does not match its sha256 (it hashes to {sha256_hex(data)[:12]})"
            )
            raise IntegrityError(
                f"image {sha[:12]} of spool record {record.seq} ({record.serial}) {what}: {path}; "
                "it and the records after it were not synced",
                self._restore_hint(record, "put the original file back"),
            )
        return data

    def _record_sha256(
        self,
        serial: str,
        session_id: str,
        session_text: str,
        artifact_text: str | None,
        session_stored: bool,
        images: Sequence[str],
    ) -> str:
        parts = [
            _RECORD_DOMAIN,
            self.station,
            self.store,
            serial,
            session_id,
            session_text,
            artifact_text or "",
            str(int(session_stored)),
            ",".join(images),
        ]
        return sha256_hex("\n".join(parts).encode("utf-8"))

    # one syncer at a time -------------------------------------------------------------------------

    @contextmanager
    def sync_lock(self, nothing_done: str = "synced nothing") -> Iterator[None]:
        """Hold the spool's sync lock; refused at once (DatabaseError, exit 2) while another process holds
        it."""
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
                raise DatabaseError(
                    f"another process (pid {holder}) is syncing the spool {self.path}; this one "
                    f"{nothing_done}",
                    "let it finish (calibctl station status shows what is left)",
                ) from exc
            os.ftruncate(fd, 0)
            os.pwrite(fd, str(os.getpid()).encode("ascii"), 0)
            yield
        finally:
            os.close(fd)  # closing the descriptor releases the flock


def _record_of(r: tuple[Any, ...]) -> SpoolRecord:
    """A ``units`` row, its columns in ``_UNITS_COLUMNS`` order."""
    return SpoolRecord(
        int(r[0]),
        r[1],
        r[2],
        r[3],
        r[4],
        r[5],
        bool(r[6]),
        tuple(json.loads(r[7])),
        r[8],
        r[9],
        r[10],
        r[11],
        r[12],
        r[13],
        r[14],
        r[15],
    )


def _seal_message(seq: int, record_sha256: str) -> bytes:
    """What a record's signature is taken over: its number (the sync order) and its sha256 (what it
    queues)."""
    return f"calibctl-spool-record-v1\n{seq}\n{record_sha256}".encode("ascii")


def default_spool_path(station_file: str | None, db_url: str) -> Path:
    """``calibctl-spool.sqlite`` in the station's folder: the station file's, else the SQLite store's, else
    ``.``."""
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
        raise FileSystemError(
            f"the spool {path} cannot take the unit: {exc.message}; the unit was not queued", _FULL_HINT
        ) from exc


def _spool_error(exc: sqlite3.Error, path: Path, action: str) -> FileSystemError | InputError:
    text = str(exc).lower()
    if "full" in text or "disk i/o" in text:
        return FileSystemError(
            f"the disk of the spool {path} is full ({exc}); nothing was written to it", _FULL_HINT
        )
    if "not a database" in text or "no such table" in text:
        return InputError(
            f"{path} is not a calibctl spool ({exc})", "pass the --spool file the station writes"
        )
    return FileSystemError(f"cannot {action} the spool {path}: {exc}", "check the path and its disk")
