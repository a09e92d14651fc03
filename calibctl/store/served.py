"""The check a read makes on each record it serves when the store has keys (``signing_key`` or
``trusted_keys`` configured): what ``db verify`` would say about that one record, at the cost of a few
indexed point queries instead of a walk over its whole chain.

For a served record (a calibration artifact, the activation event that makes it active, a rig version and
its event, a capture session) this checks:

- its chain hash over its columns (``chain_hash.row_problem``);
- its link: the record before it in its stream holds ``chain_prev`` and a lower id, the record after it
  (when there is one) names its hash and has a higher id, no other record shares its position; the last
  record of a stream is the one its version counter counts (a deleted newest event or version shows);
- its signature by a trusted key, or, unsigned, no signed record before it in its stream.

Pure Python over one ``Query`` callable (named ``:param`` SQL, which both ``sqlite3`` and sqlalchemy's
``text()`` take), so ``Store``'s reads and the sqlite3 read path (``sqlite_reads``) run the same check.
A refusal is an ``UnverifiedRecord`` (exit 2: the command cannot run on it) naming the record and
``calibctl db verify``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from calibctl.errors import UnverifiedRecord
from calibctl.signing import TrustedKeys, record_message
from calibctl.store.chain_hash import SPECS, StreamSpec, row_problem, row_values

Query = Callable[[str, dict[str, Any]], list[Mapping[str, Any]]]
"""Run one SELECT with named parameters; rows as mappings of column name to value."""

TABLES = {
    "artifact": "calibration_artifacts",
    "board": "board_revisions",
    "event": "activation_events",
    "rig": "rig_calibrations",
    "rig_event": "rig_activation_events",
    "check": "check_events",
    "rig_definition": "rig_definitions",
    "session": "capture_sessions",
    "fleet": "fleet_events",
    "health": "health_reports",
}
"""Each stream's table (a test keeps it equal to ``chain.STREAMS``)."""

REFUSED_HINT = (
    "run `calibctl db verify` (with the same keys) to see every record affected; restore the store "
    "from a backup or re-import the record from a signed export"
)


def _key_filter(spec: StreamSpec, values: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    params = {f"k{i}": values[k] for i, k in enumerate(spec.key)}
    return "".join(f"{k} = :k{i} AND " for i, k in enumerate(spec.key)), params


def _link_problem(spec: StreamSpec, values: Mapping[str, Any], query: Query) -> str | None:
    table, label = TABLES[spec.name], spec.label(values)
    where, params = _key_filter(spec, values)
    seq, row_id = int(values["chain_seq"]), values["id"]
    near = query(
        f"SELECT id, chain_seq, chain_prev, chain_hash FROM {table} WHERE {where}"
        "chain_seq >= :lo AND chain_seq <= :hi",
        {**params, "lo": seq - 1, "hi": seq + 1},
    )
    at: dict[int, list[Mapping[str, Any]]] = {}
    for r in near:
        at.setdefault(int(r["chain_seq"]), []).append(r)
    if any(len(rows) > 1 for rows in at.values()):
        return f"{label}: two records share a chain position next to it (a fork written outside calibctl)"
    before, after = at.get(seq - 1, [None])[0], at.get(seq + 1, [None])[0]
    if seq > 1 and before is None:
        return f"{label} is at chain position {seq} but the record before it is missing"
    if (before["chain_hash"] if before else None) != values["chain_prev"]:
        return (
            f"{label} does not follow the record before it: a record was deleted, inserted or rewritten there"
        )
    if before is not None and row_id is not None and int(before["id"] or 0) >= int(row_id):
        return f"{label} is out of order (its id is lower than the record before it)"
    if after is not None:
        if after["chain_prev"] != values["chain_hash"]:
            return f"{label} is not the record the next one in its chain follows: it was replaced"
        if row_id is not None and int(after["id"] or 0) <= int(row_id):
            return f"{label} is out of order (its id is higher than the record after it)"
        return None
    scope, column = spec.counter
    counted = query(
        "SELECT last_value FROM version_counters WHERE scope = :scope AND key = :key",
        {"scope": scope, "key": spec.counter_key(spec.key_of(values))},
    )
    last = int(counted[0]["last_value"]) if counted else None
    if last != int(values[column]):
        return (
            f"{label} is the last record of its chain but the {scope} counter says {column} {last}: "
            "records after it were removed"
        )
    return None


def _signature_problem(
    spec: StreamSpec, values: Mapping[str, Any], query: Query, trusted: TrustedKeys
) -> str | None:
    label = spec.label(values)
    if values.get("signature") or values.get("key_id"):
        if not trusted.keys:
            # nothing to check it against (as db verify: its report says signatures were not checked)
            return None
        subject = values[spec.subject] if spec.subject else None
        problem = trusted.check(
            values.get("key_id"), values.get("signature"), record_message(str(values["chain_hash"]), subject)
        )
        return None if problem is None else f"{label} {problem}"
    where, params = _key_filter(spec, values)
    signed = query(
        f"SELECT 1 AS signed FROM {TABLES[spec.name]} WHERE {where}chain_seq < :seq "
        "AND signature IS NOT NULL LIMIT 1",
        {**params, "seq": int(values["chain_seq"])},
    )
    return f"{label} is not signed, but records before it in its chain are" if signed else None


def problem(stream: str, row: Any, query: Query, trusted: TrustedKeys) -> str | None:
    """None when ``db verify`` with ``trusted`` would not flag the record ``row`` (an ORM row or a plain row
    of every column) for its hash, link or signature; else what it would say."""
    spec = SPECS[stream]
    values = row_values(row)
    return (
        row_problem(spec, row)
        or _link_problem(spec, values, query)
        or _signature_problem(spec, values, query, trusted)
    )


def check(stream: str, row: Any, query: Query, trusted: TrustedKeys | None) -> None:
    """Refuse to serve ``row`` (UnverifiedRecord, exit 2) when ``problem`` finds one; no-op without keys."""
    if trusted is None:
        return
    found = problem(stream, row, query, trusted)
    if found is not None:
        raise UnverifiedRecord(f"{found}; refusing to serve it", REFUSED_HINT)
