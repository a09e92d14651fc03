"""The hashing half of ``chain``: what a chained record's hash is taken over and how it is checked.

Pure Python (no sqlalchemy), so the sqlite3 read path (``sqlite_reads``) checks a calibration record by
its chain hash exactly as ``Store``'s reads do: ``codec.decode_artifact(row, by_chain=True)`` on an ORM
row or on a row of plain attributes. ``chain`` adds the tables, the links and the backfill.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from calibctl.artifacts.common import jcs_bytes, sha256_hex

CHAIN_COLUMNS = frozenset({"chain_seq", "chain_prev", "chain_hash", "signature", "key_id"})
UNHASHED = CHAIN_COLUMNS | {"id"}


@dataclass(frozen=True)
class StreamSpec:
    """A chain's name and shape: ``key`` names the columns that split its table into streams (empty: one)."""

    name: str
    key: tuple[str, ...]
    subject: str | None  # a content-hash column signed beside the chain hash (portable in exports)
    label: Callable[[Mapping[Any, Any]], str]
    counter: tuple[str, str]  # (version_counters scope, the column whose maximum the counter must equal)

    def key_of(self, values: Mapping[Any, Any]) -> tuple[Any, ...]:
        return tuple(values[k] for k in self.key)

    def counter_key(self, key: tuple[Any, ...]) -> str:
        return str(key[0]) if key else self.name


SPECS: dict[str, StreamSpec] = {
    "artifact": StreamSpec(
        "artifact",
        ("serial",),
        "content_sha256",
        lambda r: f"{r['serial']}@{r['version']}",
        ("artifact", "version"),
    ),
    "board": StreamSpec(
        "board",
        ("name",),
        "payload_sha256",
        lambda r: f"board {r['name']}@{r['revision']}",
        ("board", "revision"),
    ),
    "event": StreamSpec(
        "event",
        (),
        None,
        lambda r: f"activation event {r['id']} ({r['serial']}@{r['version']}, {r['kind']})",
        ("chain", "chain_seq"),
    ),
    # revision 0007: rig versions per rig (hand-eye edges are part of the version that adds them), rig
    # activation events one stream like the cameras' (their counter row is the lock), check events per
    # serial (a serial's re-tests are read and audited with its history; stations checking different
    # cameras never wait for each other; the ('check', serial) counter row is the lock and the count).
    "rig": StreamSpec(
        "rig", ("rig",), "content_sha256", lambda r: f"rig {r['rig']}@{r['version']}", ("rig", "version")
    ),
    "rig_event": StreamSpec(
        "rig_event",
        (),
        None,
        lambda r: f"rig activation event {r['id']} ({r['rig']}@{r['version']}, {r['kind']})",
        ("chain", "chain_seq"),
    ),
    "check": StreamSpec(
        "check",
        ("serial",),
        "payload_sha256",
        lambda r: f"check {r['check_id']} of {r['serial']}@{r['version']}",
        ("check", "chain_seq"),
    ),
    # revision 0008: rig definitions (members, root, design baselines and their tolerances, which rig lint
    # and every later rig solve read), one stream for the store, so that deleting one is a gap too.
    "rig_definition": StreamSpec(
        "rig_definition",
        (),
        "payload_sha256",
        lambda r: f"rig definition {r['name']}",
        ("chain", "chain_seq"),
    ),
    # revision 0009: capture sessions (the corners every later solve, check and report reads), per serial like
    # the checks; the ('session', serial) counter row is the lock and the count.
    "session": StreamSpec(
        "session",
        ("serial",),
        "payload_sha256",
        lambda r: f"capture session {r['session_id']}",
        ("session", "chain_seq"),
    ),
    # revision 0010_fleet_diff25: the fleet's log (robots, the versions they run, rollouts), one stream.
    "fleet": StreamSpec(
        "fleet",
        (),
        "payload_sha256",
        lambda r: f"fleet event {r['id']} ({r['subject']}, {r['kind']})",
        ("chain", "chain_seq"),
    ),
    # revision 0016: the robots' health reports a promote decides on, one stream (a deleted report is a gap).
    "health": StreamSpec(
        "health",
        (),
        "payload_sha256",
        lambda r: f"health report {r['source_id']} ({r['robot']}, {r['serial']} {r['kind']})",
        ("chain", "chain_seq"),
    ),
}
"""The order is the order of the row ids in a chain head (``audit.make_head``): new streams go last."""


def _jsonable(value: Any) -> Any:
    if isinstance(value, dt.datetime):
        if value.tzinfo is None:  # SQLite hands back naive UTC when read below the ORM type
            value = value.replace(tzinfo=dt.UTC)
        return value.astimezone(dt.UTC).isoformat()
    return value


def body(values: Mapping[Any, Any]) -> dict[str, Any]:
    """The hashed part of a row: every column but id and the chain columns, NULLs left out."""
    return {n: _jsonable(v) for n, v in values.items() if n not in UNHASHED and v is not None}


def record_hash(
    stream: StreamSpec, key: tuple[Any, ...], seq: int, prev: str | None, record: dict[str, Any]
) -> str:
    envelope = {"v": 1, "stream": stream.name, "key": list(key), "seq": seq, "prev": prev, "record": record}
    return sha256_hex(jcs_bytes(envelope))


def row_values(row: Any) -> dict[str, Any]:
    """Every column of ``row`` by name: an ORM row's mapped columns, or the attributes of a plain row
    (``sqlite_reads`` builds one per ``SELECT *`` row, so it holds every column of the table)."""
    table = getattr(row, "__table__", None)
    names = [c.name for c in table.columns] if table is not None else list(vars(row))
    return {name: getattr(row, name) for name in names}


def row_problem(stream: StreamSpec, row: Any) -> str | None:
    """None when ``row``'s chain hash matches its columns (one sha256 over them, payload included), else why
    not. The cheap integrity check for bulk reads; ``db verify`` also checks the links and signatures."""
    values = row_values(row)
    if values.get("chain_hash") is None or values.get("chain_seq") is None:
        return f"{stream.label(values)} has no chain hash: it was inserted outside calibctl"
    actual = record_hash(
        stream, stream.key_of(values), values["chain_seq"], values["chain_prev"], body(values)
    )
    if actual != values["chain_hash"]:
        return f"{stream.label(values)} was changed after it was written (its chain hash no longer matches)"
    return None
