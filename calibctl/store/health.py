"""Robots' health reports in the store (revision 0011_health_reports_health25): ``HealthReportRow``.

Append-only (the migration's triggers refuse UPDATE and DELETE); each row keeps the report's canonical JSON
with its sha256, and since revision 0016 the rows are hash-chained in one stream and signed with the station's
key, because a promote decides on them: a report edited or deleted after it was ingested is refused by the
gate. A batch is written all or nothing; before it is, every report is checked against what it refers to: its
robot is registered and carries its serial, and its ``source_id`` is new (in the store and in the batch).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import Table, func, insert, select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.artifacts.health import HealthReport
from calibctl.errors import UnverifiedRecord
from calibctl.signing import Signer, record_message
from calibctl.store import chain, codec, counters, served
from calibctl.store.codec import decode_fleet_event
from calibctl.store.fleet import _registration
from calibctl.store.models import (
    ArtifactRow,
    CheckEventRow,
    FleetEventRow,
    HealthReportRow,
    RigCalibrationRow,
)
from calibctl.store.runner import Runner

_CHUNK = 500  # source ids per IN (...) query: under SQLite's bound-parameter limit
HEALTH_TABLE: Table = HealthReportRow.__table__  # type: ignore[assignment]  # a mapped class's Table
NUMBERS = ("rms_px", "verdict", "ratio", "sigma", "td_ms", "sigma_ms", "temperature_c")


@dataclass(frozen=True)
class HealthRow:
    """One stored report's numbers (the columns ``fleet trends`` reads)."""

    serial: str
    kind: str
    at: datetime
    rms_px: float | None
    verdict: str | None
    ratio: float | None
    sigma: float | None
    td_ms: float | None
    sigma_ms: float | None
    temperature_c: float | None


@dataclass(frozen=True)
class GateReport:
    """A stored report a rollout's health gate reads: who sent it about what, its verdict numbers, its
    hash."""

    source_id: str
    payload_sha256: str
    robot: str
    serial: str
    kind: str
    at: datetime
    verdict: str | None
    ratio: float | None


GATE_KINDS = ("check", "gauge", "triage")
"""The report kinds with a verdict; a time offset has none (its trend is ``fleet trends``' business)."""


def gate_problems(s: Session) -> list[str]:
    """``db verify``: every report a promote's gate decided on (recorded in the chained promote event) is
    still stored with the sha256 the promote recorded, and its payload still hashes to it."""
    out = []
    for row in s.scalars(
        select(FleetEventRow).where(FleetEventRow.kind == "promote").order_by(FleetEventRow.id)
    ):
        try:
            event = decode_fleet_event(row)
        except UnverifiedRecord:  # a damaged promote is the chain walk's to report
            continue
        for e in event.gate:
            table, key = (
                (HealthReportRow, HealthReportRow.source_id)
                if e.source == "report"
                else (CheckEventRow, CheckEventRow.check_id)
            )
            stored = s.execute(select(table.payload, table.payload_sha256).where(key == e.id)).first()
            where = f"promote of rollout {event.subject}: its gate read {e.source} {e.id}"
            if stored is None:
                out.append(f"{where}, which is not stored")
            elif stored[1] != e.sha256 or sha256_hex(stored[0].encode("utf-8")) != e.sha256:
                out.append(
                    f"{where} with sha256 {e.sha256[:12]}, the stored one differs: it was changed after the "
                    "promote decided on it"
                )
    return out


def _problems(s: Session, reports: Sequence[HealthReport]) -> list[tuple[int, str]]:
    """(index in ``reports``, why) for each report that refers to something wrong; empty when all may be
    stored."""
    carried: dict[str, set[str] | None] = {}
    for robot in {r.robot for r in reports}:
        registered = _registration(s, robot)
        carried[robot] = None if registered is None else {*registered.serials, *registered.rigs}
    ids = [r.source_id for r in reports]
    stored: set[str] = set()
    for i in range(0, len(ids), _CHUNK):
        stored.update(
            s.scalars(
                select(HealthReportRow.source_id).where(HealthReportRow.source_id.in_(ids[i : i + _CHUNK]))
            )
        )
    first = _first_calibrations(s, {r.serial for r in reports})
    seen: set[str] = set()
    out = []
    for i, r in enumerate(reports):
        serials = carried[r.robot]
        earliest = first.get(r.serial)
        if serials is None:
            out.append((i, f"robot {r.robot} is not registered"))
        elif earliest is not None and r.time < earliest:
            out.append(
                (
                    i,
                    f"time {r.time.isoformat()} is before {r.serial}'s first calibration "
                    f"({earliest.isoformat()}): the report cannot be about it (robot clock?)",
                )
            )
        elif r.serial not in serials:
            out.append(
                (
                    i,
                    f"unknown serial {r.serial}: robot {r.robot} carries "
                    f"{', '.join(sorted(serials)) or 'none'}",
                )
            )
        elif r.source_id in stored:
            out.append((i, f"duplicate report: source id {r.source_id} is stored already"))
        elif r.source_id in seen:
            out.append((i, f"duplicate report: source id {r.source_id} appears twice in this batch"))
        seen.add(r.source_id)
    return out


def _first_calibrations(s: Session, names: set[str]) -> dict[str, datetime]:
    """When each serial's (or rig's) oldest stored calibration was made: a report measured before it is about
    nothing the store holds."""
    out: dict[str, datetime] = {}
    for key, made in (
        (ArtifactRow.serial, ArtifactRow.created_at),
        (RigCalibrationRow.rig, RigCalibrationRow.created_at),
    ):
        for name, created in s.execute(
            select(key, func.min(made)).where(key.in_(sorted(names))).group_by(key)
        ):
            out.setdefault(str(name), created)
    return out


def _sealed(s: Session, rows: list[dict[str, Any]], signer: Signer | None) -> None:
    """Number, chain and (with a key) sign ``rows`` in the store's health stream (revision 0016), in order,
    under its lock (the ('chain', 'health') counter row, held until the batch commits)."""
    stream = chain.STREAMS["health"]
    first = counters.next_value(s, "chain", "health")
    if len(rows) > 1:
        counters.raise_to(s, "chain", "health", first + len(rows) - 1)
    head = chain.head_of(s, stream, ())
    prev = None if head is None else head[1]
    for seq, row in enumerate(rows, start=first):
        digest = chain.record_hash(stream, (), seq, prev, chain.body(row))
        row.update(chain_seq=seq, chain_prev=prev, chain_hash=digest, signature=None, key_id=None)
        if signer is not None:
            row.update(
                signature=signer.sign(record_message(digest, row["payload_sha256"])), key_id=signer.key_id
            )
        prev = digest


def _refusal(s: Session, rows: Sequence[HealthReportRow], runner: Runner, reader: str) -> None:
    """Refuse (UnverifiedRecord naming it) a report ``reader`` would read that is not as ingested: its
    payload, its columns (its chain hash covers both) and, with keys, its link and signature; and any report
    deleted from the health stream since it was ingested (positions 1..N, N its counter, each held once: a gap
    is a deletion)."""
    for row in rows:
        what = f"health report {row.source_id}"
        actual = sha256_hex(row.payload.encode("utf-8"))
        problem = (
            None
            if actual == row.payload_sha256
            else f"{what} does not match its recorded sha256: it was changed after it was ingested"
        ) or chain.row_problem(chain.STREAMS["health"], row)
        if problem is not None:
            raise UnverifiedRecord(f"{problem}; {reader} refuses to read it", served.REFUSED_HINT)
        runner.served(s, "health", row)
    counted = counters.peek(s, "chain", "health") or 0
    held, lowest, highest = s.execute(
        select(func.count(), func.min(HealthReportRow.chain_seq), func.max(HealthReportRow.chain_seq))
    ).one()
    if held != counted or (held and (lowest != 1 or highest != counted)):
        raise UnverifiedRecord(
            f"the store's health reports are numbered 1 to {counted} but {held} are stored: a report was "
            f"deleted (or inserted) outside calibctl; {reader} refuses to decide",
            served.REFUSED_HINT,
        )


class HealthStore:
    """The Store's health reports."""

    def __init__(self, runner: Runner) -> None:
        self._runner = runner

    def add_health_reports(self, reports: Sequence[HealthReport]) -> list[tuple[int, str]]:
        """Store ``reports`` in one transaction, or none of them: the (index, why) of each refused one (then
        nothing is written; empty when all were stored). A concurrent writer storing the same source id makes
        the unique key refuse the batch (DatabaseError), never a second copy."""

        def work(s: Session) -> list[tuple[int, str]]:
            problems = _problems(s, reports)
            if problems or not reports:
                return problems
            now = utc_now()
            rows = []
            for r in reports:
                payload = codec.canonical_text(r)
                rows.append(
                    {
                        "source_id": r.source_id,
                        "serial": r.serial,
                        "robot": r.robot,
                        "kind": r.kind,
                        "at": r.time,
                        **{n: getattr(r, n) for n in NUMBERS},
                        "ingested_at": now,
                        "payload": payload,
                        "payload_sha256": sha256_hex(payload.encode("utf-8")),
                    }
                )
            _sealed(s, rows, self._runner.signer)
            # Core executemany (the table's INSERT compiled once, batched by the driver), not the ORM's bulk
            # path, which costs about 2 ms a row on PostgreSQL (benchmarks/results/fleet_scale.md)
            s.connection().execute(insert(HEALTH_TABLE), rows)
            return []

        return self._runner.run(work, write=True)

    def health_rows(self, serial: str) -> list[HealthRow]:
        """Every stored report on ``serial``, oldest first, each checked as the health gate checks the reports
        it reads (UnverifiedRecord naming one edited, re-chained or deleted since it was ingested)."""
        stmt = (
            select(HealthReportRow)
            .where(HealthReportRow.serial == serial)
            .order_by(HealthReportRow.at, HealthReportRow.id)
        )

        def work(s: Session) -> list[HealthRow]:
            rows = list(s.scalars(stmt))
            _refusal(s, rows, self._runner, "fleet trends")
            return [HealthRow(*(getattr(r, n) for n in ("serial", "kind", "at", *NUMBERS))) for r in rows]

        return self._runner.run(work)

    def fleet_check_rms(self, since: datetime | None = None) -> dict[str, tuple[float, int]]:
        """Serial -> (mean check RMS px, number of check reports), over every serial with check reports
        measured at or after ``since`` (index kind, at, serial, rms_px: the window's rows only, not the whole
        table)."""
        stmt = (
            select(HealthReportRow.serial, func.avg(HealthReportRow.rms_px), func.count())
            .where(HealthReportRow.kind == "check", *([] if since is None else [HealthReportRow.at >= since]))
            .group_by(HealthReportRow.serial)
        )
        return self._runner.run(
            lambda s: {str(serial): (float(mean), int(n)) for serial, mean, n in s.execute(stmt)}
        )

    def gate_reports(
        self, robots: Sequence[str], serials: Sequence[str], since: datetime
    ) -> list[GateReport]:
        """Reports with a verdict (check, gauge, triage) from ``robots`` on ``serials`` (serials or rigs)
        measured at or after ``since``, oldest first: a rollout's health gate inputs."""
        cols = [
            HealthReportRow.source_id,
            HealthReportRow.payload_sha256,
            HealthReportRow.robot,
            HealthReportRow.serial,
            HealthReportRow.kind,
            HealthReportRow.at,
            HealthReportRow.verdict,
            HealthReportRow.ratio,
        ]
        stmt = (
            select(HealthReportRow)
            .where(
                HealthReportRow.serial.in_(list(serials)),
                HealthReportRow.kind.in_(GATE_KINDS),
                HealthReportRow.at >= since,
                HealthReportRow.robot.in_(list(robots)),
            )
            .order_by(HealthReportRow.at, HealthReportRow.id)
        )
        if not robots or not serials:
            return []

        def work(s: Session) -> list[GateReport]:
            rows = list(s.scalars(stmt))
            _refusal(s, rows, self._runner, "the health gate")
            return [GateReport(**{c.key: getattr(r, c.key) for c in cols}) for r in rows]

        return self._runner.run(work)

    def health_report_count(self) -> int:
        return self._runner.run(
            lambda s: int(s.scalar(select(func.count()).select_from(HealthReportRow)) or 0)
        )
