"""Hash chains over the store's immutable records: one generic helper for every chained table.

Each chained row carries ``chain_seq`` (its position in its stream, from 1), ``chain_prev`` (the
``chain_hash`` of the record before it, NULL for the first) and ``chain_hash``:

    sha256(JCS({"v": 1, "stream": NAME, "key": [KEY...], "seq": N, "prev": PREV, "record": BODY}))

BODY is every column of the row except ``id`` and the chain/signature columns, with NULLs left out
(so a nullable column added by a later migration keeps old hashes valid; setting or clearing a
value still changes the hash); datetimes are ISO 8601 UTC. A stream is a table plus the columns
that split it: calibration artifacts per serial, board revisions per board name, activation events
one stream for the whole store; since revision 0007 also rig versions per rig, rig activation events
one stream, check events per serial; since 0008 rig definitions, one stream; since 0009 capture
sessions, per serial. Editing, deleting, inserting or reordering any record breaks the chain at the next
record; rewriting a whole stream's tail is caught by signatures (the forger has no key) or by a chain head
kept elsewhere (``db verify --head``).

The hashing itself (``body``, ``record_hash``, ``row_problem``) is in ``chain_hash``, which imports no
sqlalchemy (the sqlite3 read path checks with it). A new table joins with a ``StreamSpec`` in
``chain_hash.SPECS``, its model in ``_MODELS`` here, and a call to ``link`` before its insert.
The caller holds the stream's lock (a version counter row) so concurrent writers never fork it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Column, Connection, Integer, MetaData, String, Table, Text, select, text
from sqlalchemy.orm import Session

from calibctl.signing import Signer, record_message
from calibctl.store.chain_hash import (  # the hashing itself, shared with the sqlite3 read path
    CHAIN_COLUMNS,
    SPECS,
    UNHASHED,
    StreamSpec,
    body,
    record_hash,
    row_problem,
)
from calibctl.store.models import (
    ArtifactRow,
    Base,
    BoardRow,
    CheckEventRow,
    EventRow,
    FleetEventRow,
    HealthReportRow,
    RigCalibrationRow,
    RigEventRow,
    RigRow,
    SessionRow,
)

__all__ = [
    "CHAIN_COLUMNS",
    "STREAMS",
    "UNHASHED",
    "Stream",
    "backfill",
    "backfill_without_triggers",
    "body",
    "head_of",
    "link",
    "new_columns",
    "record_hash",
    "row_problem",
]


@dataclass(frozen=True)
class Stream(StreamSpec):
    """A chained table: its ``StreamSpec`` and the ORM model of the table."""

    model: type[Base]

    @property
    def table(self) -> Table:
        return self.model.__table__  # type: ignore[return-value]


_MODELS: dict[str, type[Base]] = {
    "artifact": ArtifactRow,
    "board": BoardRow,
    "event": EventRow,
    "rig": RigCalibrationRow,
    "rig_event": RigEventRow,
    "check": CheckEventRow,
    "rig_definition": RigRow,
    "session": SessionRow,
    "fleet": FleetEventRow,
    "health": HealthReportRow,
}
STREAMS: dict[str, Stream] = {
    name: Stream(spec.name, spec.key, spec.subject, spec.label, spec.counter, _MODELS[name])
    for name, spec in SPECS.items()
}
"""``chain_hash.SPECS`` with their tables, in the same order (the order of the row ids in a chain head)."""


def head_of(s: Session, stream: Stream, key: tuple[Any, ...]) -> tuple[int, str] | None:
    """(seq, hash) of the last record of one stream, or None when it is empty."""
    t = stream.table
    where = [t.c[k] == v for k, v in zip(stream.key, key, strict=True)]
    row = s.execute(
        select(t.c.chain_seq, t.c.chain_hash).where(*where).order_by(t.c.chain_seq.desc()).limit(1)
    ).first()
    return None if row is None else (int(row[0]), str(row[1]))


def link(s: Session, stream: Stream, row: Base, signer: Signer | None) -> None:
    """Set the chain (and signature) columns of ``row`` before it is inserted; the caller holds the lock."""
    values = {c.name: getattr(row, c.name) for c in stream.table.columns}
    key = stream.key_of(values)
    head = head_of(s, stream, key)
    seq, prev = (1, None) if head is None else (head[0] + 1, head[1])
    digest = record_hash(stream, key, seq, prev, body(values))
    row.chain_seq, row.chain_prev, row.chain_hash = seq, prev, digest  # type: ignore[attr-defined]
    if signer is not None:
        subject = values[stream.subject] if stream.subject else None
        row.signature = signer.sign(record_message(digest, subject))  # type: ignore[attr-defined]
        row.key_id = signer.key_id  # type: ignore[attr-defined]


def backfill(conn: Connection, names: tuple[str, ...]) -> None:
    """Chain the rows of streams ``names`` written before they were chained, in id order (migrations 0005
    and 0007; never signed: no key is at hand in a migration). Tables are reflected, so later columns do
    not matter here. A stream counted by its chain position gets its counter rows."""
    meta = MetaData()
    for stream in (STREAMS[n] for n in names):
        t = Table(stream.table.name, meta, autoload_with=conn)
        heads: dict[tuple[Any, ...], tuple[int, str]] = {}
        for row in conn.execute(select(t).order_by(t.c.id)).mappings().all():
            key = stream.key_of(row)
            seq, prev = heads.get(key, (0, None))
            digest = record_hash(stream, key, seq + 1, prev, body(row))
            conn.execute(
                t.update()
                .where(t.c.id == row["id"])
                .values(chain_seq=seq + 1, chain_prev=prev, chain_hash=digest)
            )
            heads[key] = (seq + 1, digest)
        if stream.counter[1] == "chain_seq" and heads:  # its position is counted in version_counters
            counters = Table("version_counters", meta, autoload_with=conn)
            # imported here, as in counters.py: sqlalchemy.dialects.postgresql alone costs ~0.1 s of start-up
            insert: Any
            if conn.dialect.name == "postgresql":
                from sqlalchemy.dialects.postgresql import insert as pg_insert

                insert = pg_insert(counters)
            else:
                from sqlalchemy.dialects.sqlite import insert as sqlite_insert

                insert = sqlite_insert(counters)
            conn.execute(
                insert,
                [
                    {"scope": stream.counter[0], "key": stream.counter_key(key), "last_value": seq}
                    for key, (seq, _) in heads.items()
                ],
            )


def new_columns() -> list[Column[Any]]:
    """The chain columns a migration adds to a table joining the chains (0005, 0007)."""
    return [
        Column("chain_seq", Integer(), nullable=True),
        Column("chain_prev", String(64), nullable=True),
        Column("chain_hash", String(64), nullable=True),
        Column("signature", Text(), nullable=True),
        Column("key_id", String(64), nullable=True),
    ]


def backfill_without_triggers(
    conn: Connection, names: tuple[str, ...], prepare: Callable[[Connection], None] | None = None
) -> None:
    """``backfill`` with the tables' immutability triggers lifted for that one UPDATE and restored;
    ``prepare`` runs first, inside the same window (0008 numbers the rig definitions there)."""

    def work() -> None:
        if prepare is not None:
            prepare(conn)
        backfill(conn, names)

    tables = [STREAMS[n].table.name for n in names]
    if conn.dialect.name == "sqlite":
        listed = ", ".join(f"'trg_{t}_no_update'" for t in tables)
        saved = conn.execute(
            text(f"SELECT name, sql FROM sqlite_master WHERE type = 'trigger' AND name IN ({listed})")
        ).all()
        for name, _ in saved:
            conn.execute(text(f"DROP TRIGGER {name}"))
        work()
        for _, sql in saved:
            conn.execute(text(sql))
        return
    for table in tables:
        conn.execute(text(f"ALTER TABLE {table} DISABLE TRIGGER trg_{table}_immutable"))
    work()
    for table in tables:
        conn.execute(text(f"ALTER TABLE {table} ENABLE TRIGGER trg_{table}_immutable"))
