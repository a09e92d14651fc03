"""``db verify``: every chain, signature, counter and activation event, in bulk reads.

Checked for every chained stream (see ``chain``): positions 1..N with no gap or duplicate, each
record's ``chain_prev`` equal to the hash of the record before it, its ``chain_hash`` recomputed from
its columns, ids increasing along the chain (reads order events by id), versions strictly increasing,
the version counter equal to the highest version, and the signature by a trusted key. The streams
are camera artifacts, board revisions, activation events, (revision 0007) rig versions, rig
activation events and check events, (revision 0008) rig definitions and (revision 0009) capture
sessions. A counter whose records were all deleted is named too. Activation
events must name an accepted artifact and the version that was active before them. Documents are
re-hashed by ``codec`` (content hash re-derived, and column copies).

A *chain head* (``HEAD``) is ``calibctl-head-v1:<ids>:<digest>``: the highest row id of every chained
table and a sha256 over the last (position, hash) of every stream at that point. ``--since HEAD``
proves the heads are still the ones HEAD names (so nothing before it was rewritten or truncated
without re-chaining, and re-chaining needs the signing key), then checks in full every row written
after it by *position* (``_after``: past its stream's head position, in a new stream, without a
position, or with a higher id - a forged row given a low id is not skipped), and looks for positions
held twice anywhere; of the older activation events only each name's last one is read, to check the
new events against what was active. When the heads no longer hash to HEAD, every row is checked.
Every mode also checks that the immutability triggers are in place (``triggers``) and that each fleet
checkpoint is the fleet log replayed up to its event (``fleet_checkpoints.problems``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import ColumnElement, FromClause, and_, func, not_, or_, select, true
from sqlalchemy.orm import Session

from calibctl.artifacts.common import jcs_bytes, sha256_hex
from calibctl.errors import UnverifiedRecord, UsageError
from calibctl.signing import TrustedKeys, record_message
from calibctl.store import chain, codec, fleet_checkpoints, health, rigs, triggers
from calibctl.store.models import (
    ArtifactRow,
    CounterRow,
    EventRow,
    RigCalibrationRow,
    RigEventRow,
)

HEAD_PREFIX = "calibctl-head-v1"
_DECODERS: dict[str, Callable[[Any], object]] = {
    "artifact": codec.decode_artifact,
    "board": codec.decode_board,
    "rig": rigs.decode_calibration,
    "check": codec.decode_check,
    "rig_definition": rigs.decode_definition,
    "session": codec.decode_session,
    "fleet": codec.decode_fleet_event,
}
_VERSION = {"artifact": "version", "board": "revision", "rig": "version"}


@dataclass
class Audit:
    problems: list[str] = field(default_factory=list)
    unsigned: int = 0
    signatures_checked: int = 0
    records_checked: int = 0
    heads: dict[str, dict[tuple[Any, ...], tuple[int, str]]] = field(default_factory=dict)
    last_ids: dict[str, int] = field(default_factory=dict)

    def head(self) -> str:
        return make_head(self.last_ids, self.heads)


def _digest(heads: dict[str, dict[tuple[Any, ...], tuple[int, str]]]) -> str:
    flat = sorted(
        [name, list(key), seq, digest]
        for name, by_key in heads.items()
        for key, (seq, digest) in by_key.items()
    )
    return sha256_hex(jcs_bytes(flat))


def make_head(last_ids: dict[str, int], heads: dict[str, dict[tuple[Any, ...], tuple[int, str]]]) -> str:
    ids = ".".join(str(last_ids.get(name, 0)) for name in chain.STREAMS)
    return f"{HEAD_PREFIX}:{ids}:{_digest(heads)}"


def parse_head(text: str) -> tuple[dict[str, int], str]:
    """A head printed before a stream joined the chains (revision 0007) names fewer streams: the missing
    ones count from id 0, so their records are checked in full (they were not part of its digest)."""
    parts = text.strip().split(":")
    ids = parts[1].split(".") if len(parts) == 3 else []
    if (
        len(parts) != 3
        or parts[0] != HEAD_PREFIX
        or not 3 <= len(ids) <= len(chain.STREAMS)
        or not all(i.isdigit() for i in ids)
    ):
        raise UsageError(f"'{text}' is not a chain head", "pass what `calibctl db verify --head` printed")
    ids += ["0"] * (len(chain.STREAMS) - len(ids))
    return dict(zip(chain.STREAMS, (int(i) for i in ids), strict=True)), parts[2]


def _heads_at(s: Session, stream: chain.Stream, last_id: int) -> dict[tuple[Any, ...], tuple[int, str]]:
    """The last (seq, hash) of each stream among rows with id <= last_id (one grouped query)."""
    t = stream.table
    keys = [t.c[k] for k in stream.key]
    latest = (
        select(*keys, func.max(t.c.chain_seq).label("seq"))
        .where(t.c.id <= last_id)
        .group_by(*keys)
        .subquery()
    )
    joined = and_(*(t.c[k] == latest.c[k] for k in stream.key), t.c.chain_seq == latest.c.seq)
    rows = s.execute(select(*keys, t.c.chain_seq, t.c.chain_hash).join(latest, joined)).all()
    return {tuple(r[: len(keys)]): (int(r[-2]), str(r[-1])) for r in rows if r[-2] is not None}


def _check_signature(
    audit: Audit, stream: chain.Stream, row: Any, trusted: TrustedKeys, require: bool, after_signed: bool
) -> None:
    """``after_signed``: a record before it in its stream is signed. Once a store signs, every writer must:
    an unsigned record there is what a forger without the key would add."""
    if not row["signature"] and not row["key_id"]:
        audit.unsigned += 1
        if require or after_signed:
            why = "" if require else ", but records before it in its chain are"
            audit.problems.append(f"{stream.label(row)} is not signed{why}")
        return
    if not trusted.keys:
        return  # nothing to check against; the report says signatures were not checked
    subject = row[stream.subject] if stream.subject else None
    problem = trusted.check(row["key_id"], row["signature"], record_message(str(row["chain_hash"]), subject))
    audit.signatures_checked += 1
    if problem is not None:
        audit.problems.append(f"{stream.label(row)} {problem}")


def _after(stream: chain.Stream, since: int | None) -> tuple[FromClause, ColumnElement[bool]]:
    """The rows of ``stream`` written after a head whose last id there was ``since`` (None: every row), by
    *position*, whatever their id: past the head's last position of their stream, in a stream the head did not
    have, without a position, or with a higher id. (FROM clause, WHERE clause) for a select of the table."""
    t = stream.table
    if since is None:
        return t, true()
    keys = [t.c[k] for k in stream.key]
    latest = (
        select(*keys, func.max(t.c.chain_seq).label("seq")).where(t.c.id <= since).group_by(*keys).subquery()
    )
    on = and_(*(t.c[k] == latest.c[k] for k in stream.key)) if stream.key else true()
    newer = or_(
        t.c.id > since,
        t.c.id.is_(None),
        t.c.chain_seq.is_(None),
        t.c.chain_seq < 1,  # a forged row at position 0 (or below) precedes every head
        latest.c.seq.is_(None),
        t.c.chain_seq > latest.c.seq,
    )
    return t.outerjoin(latest, on), newer


def _duplicates(s: Session, audit: Audit, stream: chain.Stream) -> None:
    """Positions held by two records anywhere in the table (one grouped query): in ``--since`` mode a record
    added at an old position below the head's ids is found here, not by the walk."""
    t = stream.table
    keys = [t.c[k] for k in stream.key]
    for row in s.execute(
        select(*keys, t.c.chain_seq)
        .where(t.c.chain_seq.is_not(None))
        .group_by(*keys, t.c.chain_seq)
        .having(func.count() > 1)
    ):
        of = f" of {' '.join(str(v) for v in row[:-1])}" if stream.key else ""
        audit.problems.append(
            f"position {row[-1]} of the {stream.name} chain{of} is held by more than one record: "
            "one was added outside calibctl"
        )


def _signed_before(s: Session, stream: chain.Stream, key: tuple[Any, ...], seq: int) -> bool:
    """Whether a record at or before position ``seq`` of one stream is signed (``--since``: the walk starts
    after the head, and an unsigned record after a signed one before it is still a finding)."""
    t = stream.table
    where = [t.c[k] == v for k, v in zip(stream.key, key, strict=True)]
    return (
        s.execute(
            select(t.c.id).where(*where, t.c.chain_seq <= seq, t.c.signature.is_not(None)).limit(1)
        ).first()
        is not None
    )


def _walk(
    s: Session,
    audit: Audit,
    stream: chain.Stream,
    since: int | None,
    start: dict[tuple[Any, ...], tuple[int, str]],
    trusted: TrustedKeys,
    require: bool,
) -> None:
    """Check one chained table's rows written after ``since`` (``_after``), stream by stream, in chain
    order."""
    t = stream.table
    order = [t.c[k] for k in stream.key] + [t.c.chain_seq, t.c.id]
    heads = audit.heads.setdefault(stream.name, dict(start))
    key: tuple[Any, ...] | None = None
    seq, prev, last_id, last_version, signed = 0, None, 0, 0, False
    version_col = _VERSION.get(stream.name)
    joined, newer = _after(stream, since)
    query = select(t).select_from(joined).where(newer).order_by(*order).execution_options(yield_per=500)
    for row in s.execute(query).mappings():
        audit.records_checked += 1
        label = stream.label(row)
        audit.last_ids[stream.name] = max(audit.last_ids.get(stream.name, 0), int(row["id"] or 0))
        if stream.key_of(row) != key:
            key = stream.key_of(row)
            seq, prev = start.get(key, (0, None))
            last_id, last_version, signed = 0, 0, seq > 0 and _signed_before(s, stream, key, seq)
        if row["chain_hash"] is None or row["chain_seq"] is None:
            audit.problems.append(f"{label} has no chain hash: it was inserted outside calibctl")
            continue
        if int(row["chain_seq"]) < 1:  # before the first position: in no chain; the walk goes on past it
            audit.problems.append(
                f"{label} is at chain position {row['chain_seq']}, before the first: it was inserted outside "
                "calibctl"
            )
            continue
        if row["chain_seq"] == seq:
            audit.problems.append(f"{label} duplicates position {seq} of its chain")
        elif row["chain_seq"] != seq + 1:
            audit.problems.append(
                f"{label} is at chain position {row['chain_seq']} but {seq + 1} was expected: "
                "records before it are missing"
            )
        elif row["chain_prev"] != prev:
            audit.problems.append(
                f"{label} does not follow the record before it: a record was deleted, inserted "
                "or rewritten there"
            )
        actual = chain.record_hash(stream, key, int(row["chain_seq"]), row["chain_prev"], chain.body(row))
        if actual != row["chain_hash"]:
            audit.problems.append(
                f"{label} was changed after it was written (its chain hash no longer matches)"
            )
        if int(row["id"] or 0) <= last_id:
            audit.problems.append(f"{label} is out of order (its id is lower than the record before it)")
        if version_col is not None:
            if int(row[version_col]) <= last_version:
                audit.problems.append(
                    f"{label}: {version_col} {row[version_col]} repeats or goes back along the chain"
                )
            last_version = int(row[version_col])
        _check_signature(audit, stream, row, trusted, require, signed)
        signed = signed or bool(row["signature"])
        seq, prev, last_id = int(row["chain_seq"]), str(row["chain_hash"]), int(row["id"])
        heads[key] = (seq, prev)


def _check_counters(s: Session, audit: Audit, stream: chain.Stream) -> None:
    scope, column = stream.counter
    t = stream.table
    keys = [t.c[k] for k in stream.key]
    highest = {
        tuple(r[:-1]): int(r[-1])
        for r in s.execute(select(*keys, func.max(t.c[column])).group_by(*keys))
        if r[-1]
    }
    counters = {
        str(k): int(v)
        for k, v in s.execute(select(CounterRow.key, CounterRow.last_value).where(CounterRow.scope == scope))
    }
    for key, value in highest.items():
        name = stream.counter_key(key)
        if counters.get(name) != value:
            audit.problems.append(
                f"the {scope} counter of {name} is {counters.get(name)} but the highest {column} "
                f"stored is {value}: the counter or the records were changed"
            )
    # a counter with no record left: every record of that stream was deleted (the scope 'chain' is shared by
    # the key-less streams, each counted under its own name)
    mine = {stream.counter_key(k) for k in highest}
    for name, value in counters.items():
        if name not in mine and (stream.key or name == stream.name) and value > 0:
            audit.problems.append(
                f"the {scope} counter of {name} is {value} but no record of it is stored: "
                "its records were deleted"
            )


def _check_events(s: Session, audit: Audit, since: int | None, stream: str = "event") -> None:
    """Every activation event (camera, or with ``stream="rig_event"`` rig) written after ``since``
    (``_after``) names a stored, accepted version and the version that was active before it."""
    events, versions, key = (
        (EventRow, ArtifactRow, "serial") if stream == "event" else (RigEventRow, RigCalibrationRow, "rig")
    )
    ev, ver = events.__table__.c, versions.__table__.c
    joined, newer = _after(chain.STREAMS[stream], since)
    named = select(ev[key]).select_from(joined).where(newer)  # only the names the checked events name
    status = {
        (name, int(v)): st
        for name, v, st in s.execute(select(ver[key], ver.version, ver.status).where(ver[key].in_(named)))
    }
    # what was active at the head: each name's last event before it, in one grouped query
    last = (
        select(ev[key], func.max(ev.id).label("id"))
        .select_from(joined)
        .where(not_(newer))
        .group_by(ev[key])
        .subquery()
    )
    active: dict[str, int] = {
        n: int(v) for n, v in s.execute(select(ev[key], ev.version).join(last, ev.id == last.c.id))
    }
    rows = s.execute(
        select(ev.id, ev[key], ev.version, ev.previous_version, ev.kind)
        .select_from(joined)
        .where(newer)
        .order_by(ev.id)
    ).mappings()
    prefix = "" if stream == "event" else "rig "
    for row in rows:
        name, version = row[key], int(row["version"])
        label = chain.STREAMS[stream].label(row)
        if (name, version) not in status:
            audit.problems.append(f"{label} names {prefix}{name}@{version}, which is not stored")
        elif status[(name, version)] != "accepted":
            audit.problems.append(f"{label} activates {prefix}{name}@{version}, which is not accepted")
        if row["previous_version"] != active.get(name):
            audit.problems.append(
                f"{label} says {row['previous_version']} was active before it, but the log "
                f"says {active.get(name)}"
            )
        active[name] = version


def run(
    s: Session, trusted: TrustedKeys, *, require_signature: bool = False, since: str | None = None
) -> Audit:
    """The whole audit (or, with ``since``, the part written after that chain head)."""
    audit = Audit(problems=triggers.problems(s))
    last_ids = {name: 0 for name in chain.STREAMS}
    starts: dict[str, dict[tuple[Any, ...], tuple[int, str]]] = {name: {} for name in chain.STREAMS}
    after: dict[str, int | None] = dict.fromkeys(chain.STREAMS)
    if since is not None:
        last_ids, digest = parse_head(since)
        after = {name: last_ids[name] for name in chain.STREAMS}
        starts = {name: _heads_at(s, stream, last_ids[name]) for name, stream in chain.STREAMS.items()}
        if _digest(starts) != digest:  # then nothing before it can be taken as checked: check every row
            audit.problems.append(
                "the history up to the given chain head was rewritten or truncated: its stream "
                "heads no longer hash to it"
            )
            last_ids, after = {name: 0 for name in chain.STREAMS}, dict.fromkeys(chain.STREAMS)
            starts = {name: {} for name in chain.STREAMS}
    audit.last_ids = dict(last_ids)
    for name, stream in chain.STREAMS.items():
        if since is not None:
            _duplicates(s, audit, stream)
        _walk(s, audit, stream, after[name], starts[name], trusted, require_signature)
        _check_counters(s, audit, stream)
    _check_events(s, audit, after["event"])
    _check_events(s, audit, after["rig_event"], "rig_event")
    for name, decode in _DECODERS.items():
        t = chain.STREAMS[name].model
        joined, newer = _after(chain.STREAMS[name], after[name])
        for row in s.scalars(select(t).select_from(joined).where(newer).execution_options(yield_per=500)):
            try:
                decode(row)
            except UnverifiedRecord as exc:
                audit.problems.append(exc.message)
    audit.problems.extend(health.gate_problems(s))
    audit.problems.extend(fleet_checkpoints.problems(s, trusted))
    return audit
