"""Fleet checkpoints (revision 0015_checkpoints_fleet_ckpt): the fleet log replayed up to event N, so a read
replays only the events after the newest one instead of the whole log.

Derived data, never the source of truth. A checkpoint is used only when event N's chain hash is still the one
it recorded, its state still matches its sha256 and is of this calibctl's format; otherwise the next older one
is tried, then the whole log. ``db verify`` re-derives every checkpoint from the log (``problems``).

Written by the fleet writer (``append_fleet_events``), in the same transaction as the events, once the log is
``EVERY`` events past the newest checkpoint: the writer holds the fleet's lock, so the state is of exactly the
log it wrote, and read commands (``fleet status`` on a read-only copy of the store included) never write.
The cost, a replay of at most ``EVERY`` events from the previous checkpoint, is paid once per ``EVERY``
events; a store migrated with a long log gets its first one at the next fleet write.

Signed: with a station key the writer signs each checkpoint (its position, event N's chain hash and the
state's sha256), and a store with keys (``Store.trusted``) uses only a checkpoint signed by a trusted key, so
rewriting a checkpoint together with its sha256 is no longer a way to change what ``fleet status`` serves
(``db verify`` replays the log and catches it either way). A store without keys checks the chain hash and the
sha256 only.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import delete, func, select, text
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.artifacts.fleet import FleetEvent
from calibctl.errors import UnverifiedRecord
from calibctl.signing import Signer, TrustedKeys, record_message
from calibctl.store import chain_hash, served
from calibctl.store.codec import decode_fleet_event
from calibctl.store.fleet_ledger import STATE_FORMAT, Fleet, from_state, rollout_positions, to_state
from calibctl.store.models import CounterRow, FleetCheckpointRow, FleetEventRow

EVERY = 1000
"""Events between checkpoints: a read replays at most this many past the newest (20-80 ms of CPU for 1 000
events,
benchmarks/bench_fleet_checkpoint.py); writing one costs the writer a replay of as many, once."""

KEEP = 3
"""Checkpoints kept (newest first): a read falls back to an older one when the newest does not match the
log."""


@dataclass
class Loaded:
    """The log replayed (not settled): from the checkpoint at ``since`` (0: none), then the events after
    it."""

    fleet: Fleet
    since: int = 0
    last_hash: str | None = None  # the chain hash of event ``fleet.length``
    ignored: list[str] = field(default_factory=list)  # why newer checkpoints were not used


def _message(position: int, chain_hash: str, state_sha256: str) -> bytes:
    """The bytes a checkpoint's signature is taken over."""
    return record_message(state_sha256, f"fleet-checkpoint {position} {chain_hash}")


def _state_text(fleet: Fleet) -> str:
    return json.dumps(to_state(fleet), separators=(",", ":"), ensure_ascii=False)


def _usable(
    s: Session, row: FleetCheckpointRow, *, rollouts: bool, trusted: TrustedKeys | None
) -> Fleet | str:
    """The checkpoint's fleet, or why it cannot be used (``rollouts``: with its rollouts' events read from the
    log;
    else stand-ins, see ``from_state``)."""
    at = f"fleet checkpoint at event {row.position}"
    if row.format != STATE_FORMAT:
        return f"{at} is of state format {row.format}, not {STATE_FORMAT} (written by another calibctl)"
    log_hash = s.scalar(select(FleetEventRow.chain_hash).where(FleetEventRow.id == row.position))
    if log_hash != row.chain_hash:
        why = "no such event" if log_hash is None else "the log was rewritten or the checkpoint forged"
        return f"{at} does not match the log's chain hash there ({why})"
    if sha256_hex(row.state.encode("utf-8")) != row.state_sha256:
        return f"{at} was changed after it was written (its state no longer matches its sha256)"
    if trusted is not None:
        unsigned = trusted.check(
            row.key_id, row.signature, _message(row.position, row.chain_hash, row.state_sha256)
        )
        if unsigned is not None:
            return f"{at} {unsigned} (a store with keys uses only checkpoints signed by a trusted key)"
    try:
        state = json.loads(row.state)
        positions = rollout_positions(state)
        if any(not 0 < p <= row.position for p in positions):
            raise ValueError("a rollout event past the checkpoint")
        if not rollouts:
            fleet = from_state(state, None)
        else:
            rows = (
                s.scalars(select(FleetEventRow).where(FleetEventRow.id.in_(positions))).all()
                if positions
                else []
            )
            fleet = from_state(state, {r.id: _served_event(s, r, trusted) for r in rows})
    except (KeyError, TypeError, ValueError, RecursionError) as exc:  # RecursionError: JSON nested too deep
        return f"{at} does not hold a fleet state ({type(exc).__name__}: {str(exc)[:200]})"
    if fleet.length != row.position:
        return f"{at} holds the state of event {fleet.length}"
    return fleet


def load(s: Session, *, rollouts: bool = True, trusted: TrustedKeys | None = None) -> Loaded:
    """The log replayed from the newest usable checkpoint (an undecodable event raises UnverifiedRecord, as a
    full replay does). ``rollouts=False``: the rollouts the checkpoint holds are stand-ins (for ``to_state``
    only). ``trusted``: the store's keys; with them only a checkpoint signed by one of them is used."""
    loaded = Loaded(Fleet())
    for row in s.scalars(select(FleetCheckpointRow).order_by(FleetCheckpointRow.position.desc()).limit(KEEP)):
        usable = _usable(s, row, rollouts=rollouts, trusted=trusted)
        if isinstance(usable, str):
            loaded.ignored.append(usable)
            continue
        loaded.fleet, loaded.since, loaded.last_hash = usable, row.position, row.chain_hash
        break
    tail = select(FleetEventRow).where(FleetEventRow.id > loaded.fleet.length).order_by(FleetEventRow.id)
    first_signed = s.scalar(
        select(func.min(FleetEventRow.chain_seq)).where(FleetEventRow.signature.is_not(None))
    )
    for r in s.scalars(tail.execution_options(yield_per=1000)):
        problem = _tail_problem(r, loaded, first_signed, trusted)
        if problem is not None:
            raise UnverifiedRecord(f"{problem}; refusing to serve the fleet log", served.REFUSED_HINT)
        loaded.fleet.apply(decode_fleet_event(r, by_chain=True))
        loaded.last_hash = r.chain_hash
    counted = s.scalar(
        select(CounterRow.last_value).where(CounterRow.scope == "chain", CounterRow.key == "fleet")
    )
    if loaded.fleet.length != int(counted or 0):
        raise UnverifiedRecord(
            f"the fleet log ends at event {loaded.fleet.length} but its counter says {int(counted or 0)}: "
            "events were removed; refusing to serve the fleet log",
            served.REFUSED_HINT,
        )
    return loaded


def _tail_problem(
    row: FleetEventRow, loaded: Loaded, first_signed: int | None, trusted: TrustedKeys | None
) -> str | None:
    """What ``db verify`` would say about the log's next event ``row`` after the events replayed so far: its
    place (the next position, following the hash before it) and, with keys, its signature by a trusted one or,
    unsigned, no signed event before it. Its own chain hash is ``decode_fleet_event``'s. The replay walks the
    log in order, so the link needs no query of its own (``served.check`` would cost three an event)."""
    label = chain_hash.SPECS["fleet"].label(chain_hash.row_values(row))
    if row.chain_seq != loaded.fleet.length + 1 or row.id != row.chain_seq:
        return f"{label} is at chain position {row.chain_seq} but {loaded.fleet.length + 1} was expected"
    if row.chain_prev != loaded.last_hash:
        return (
            f"{label} does not follow the event before it: an event was deleted, inserted or rewritten there"
        )
    if trusted is None:
        return None
    if row.signature or row.key_id:
        if not trusted.keys:
            return None
        why = trusted.check(
            row.key_id, row.signature, record_message(str(row.chain_hash), row.payload_sha256)
        )
        return None if why is None else f"{label} {why}"
    if first_signed is not None and first_signed < row.chain_seq:
        return f"{label} is not signed, but events before it in the fleet log are"
    return None


def _served_event(s: Session, row: FleetEventRow, trusted: TrustedKeys | None) -> FleetEvent:
    """An event before a checkpoint that the checkpoint's state reads (a rollout): its chain hash, its link to
    its neighbours and, with keys, its signature, as ``served`` checks any record a read serves."""
    event = decode_fleet_event(row, by_chain=True)

    def query(sql: str, params: dict[str, Any]) -> list[Mapping[str, Any]]:
        return [dict(r) for r in s.execute(text(sql), params).mappings()]

    served.check("fleet", row, query, trusted or TrustedKeys())
    return event


def write_if_due(s: Session, length: int, signer: Signer | None = None) -> None:
    """After the fleet writer appended up to event ``length`` (it holds the fleet's lock): a checkpoint there
    when the log is ``EVERY`` events past the newest one, signed with ``signer`` when there is one; all but
    the newest ``KEEP`` are deleted."""
    newest = s.scalar(select(func.max(FleetCheckpointRow.position))) or 0
    if length - newest < EVERY:
        return
    loaded = load(s, rollouts=False)  # decoding every rollout with its diffs was 2/3 of a read at 100k events
    if loaded.last_hash is None or loaded.fleet.length != length:  # pragma: no cover - the writer's own rows
        return
    text = _state_text(loaded.fleet)
    digest = sha256_hex(text.encode("utf-8"))
    signature = None if signer is None else signer.sign(_message(length, loaded.last_hash, digest))
    s.add(
        FleetCheckpointRow(
            position=length,
            chain_hash=loaded.last_hash,
            format=STATE_FORMAT,
            written_at=utc_now(),
            state=text,
            state_sha256=digest,
            signature=signature,
            key_id=None if signer is None else signer.key_id,
        )
    )
    s.flush()
    kept = select(FleetCheckpointRow.position).order_by(FleetCheckpointRow.position.desc()).limit(KEEP)
    s.execute(delete(FleetCheckpointRow).where(FleetCheckpointRow.position.not_in(kept.scalar_subquery())))


def problems(s: Session, trusted: TrustedKeys | None = None) -> list[str]:
    """``db verify``: each checkpoint of this format against the log: event N's chain hash, its sha256, its
    signature when it has one and keys are given, and its state against a replay of the log up to N (one pass
    over the log). An unsigned checkpoint is no finding (one written before the store had keys is legitimate;
    a store with keys only skips it on reads)."""
    rows = {
        r.position: r
        for r in s.scalars(select(FleetCheckpointRow).where(FleetCheckpointRow.format == STATE_FORMAT))
    }
    if not rows:
        return []
    found: list[str] = []
    fleet = Fleet()
    events = select(FleetEventRow).where(FleetEventRow.id <= max(rows)).order_by(FleetEventRow.id)
    try:
        for r in s.scalars(events.execution_options(yield_per=1000)):
            fleet.apply(decode_fleet_event(r))
            row = rows.pop(fleet.length, None)
            if row is not None:
                found += _compare(row, r.chain_hash, fleet, trusted)
    except UnverifiedRecord:  # the audit names the event itself
        return [
            *found,
            f"fleet checkpoint(s) at event(s) {', '.join(map(str, sorted(rows)))} not checked: the log "
            "before them does not decode",
        ]
    found += [
        f"fleet checkpoint at event {p} is past the end of the log ({fleet.length} events)"
        for p in sorted(rows)
    ]
    return found


def _compare(
    row: FleetCheckpointRow, log_hash: str | None, fleet: Fleet, trusted: TrustedKeys | None
) -> list[str]:
    at = f"fleet checkpoint at event {row.position}"
    if row.chain_hash != log_hash:
        return [f"{at} does not match the log's chain hash there (stale or forged; reads ignore it)"]
    if sha256_hex(row.state.encode("utf-8")) != row.state_sha256:
        return [
            f"{at} was changed after it was written (its state no longer matches its sha256; reads ignore it)"
        ]
    if row.signature is not None and trusted is not None and trusted.keys:
        why = trusted.check(
            row.key_id, row.signature, _message(row.position, row.chain_hash, row.state_sha256)
        )
        if why is not None:
            return [f"{at} {why} (reads with keys ignore it)"]
    try:
        same = json.loads(row.state) == to_state(fleet)
    except (ValueError, RecursionError):
        same = False
    return (
        []
        if same
        else [
            f"{at} is not the log replayed up to event {row.position} (derived data: delete "
            "the row, or restore the store)"
        ]
    )
