"""Robots' health reports in the store (revision 0011_health_reports_health25): ``HealthReportRow``.

Telemetry, not records: append-only (the migration's triggers refuse UPDATE and DELETE) and each row keeps the
report's canonical JSON with its sha256, but the rows are not hash-chained (docs/fleet.md says why). A batch is
written all or nothing; before it is, every report is checked against what it refers to: its robot is registered
and carries its serial, and its ``source_id`` is new (in the store and in the batch).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import Table, func, insert, select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.artifacts.health import HealthReport
from calibctl.errors import IntegrityError
from calibctl.store import codec
from calibctl.store.codec import decode_fleet_event
from calibctl.store.fleet import _registration
from calibctl.store.models import CheckEventRow, FleetEventRow, HealthReportRow
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
    """A stored report a rollout's health gate reads: who sent it about what, its verdict numbers, its hash."""

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
    """``db verify``: every report a promote's gate decided on (recorded in the chained promote event) is still
    stored with the sha256 the promote recorded, and its payload still hashes to it."""
    out = []
    for row in s.scalars(
        select(FleetEventRow).where(FleetEventRow.kind == "promote").order_by(FleetEventRow.id)
    ):
        try:
            event = decode_fleet_event(row)
        except IntegrityError:  # a damaged promote is the chain walk's to report
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
    """(index in ``reports``, why) for each report that refers to something wrong; empty when all may be stored."""
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
    seen: set[str] = set()
    out = []
    for i, r in enumerate(reports):
        serials = carried[r.robot]
        if serials is None:
            out.append((i, f"robot {r.robot} is not registered"))
        elif r.serial not in serials:
            out.append(
                (
                    i,
                    f"unknown serial {r.serial}: robot {r.robot} carries {', '.join(sorted(serials)) or 'none'}",
                )
            )
        elif r.source_id in stored:
            out.append((i, f"duplicate report: source id {r.source_id} is stored already"))
        elif r.source_id in seen:
            out.append((i, f"duplicate report: source id {r.source_id} appears twice in this batch"))
        seen.add(r.source_id)
    return out


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
            # Core executemany (the table's INSERT compiled once, batched by the driver), not the ORM's bulk path,
            # which costs about 2 ms a row on PostgreSQL (benchmarks/results/fleet_scale.md)
            s.connection().execute(insert(HEALTH_TABLE), rows)
            return []

        return self._runner.run(work, write=True)

    def health_rows(self, serial: str) -> list[HealthRow]:
        """Every stored report on ``serial``, oldest first."""
        cols = [getattr(HealthReportRow, n) for n in ("serial", "kind", "at", *NUMBERS)]
        return self._runner.run(
            lambda s: [
                HealthRow(*row)
                for row in s.execute(
                    select(*cols)
                    .where(HealthReportRow.serial == serial)
                    .order_by(HealthReportRow.at, HealthReportRow.id)
                )
            ]
        )

    def fleet_check_rms(self, since: datetime | None = None) -> dict[str, tuple[float, int]]:
        """Serial -> (mean check RMS px, number of check reports), over every serial with check reports measured at
        or after ``since`` (index kind, at, serial, rms_px: the window's rows only, not the whole table)."""
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
        """Reports with a verdict (check, gauge, triage) from ``robots`` on ``serials`` (serials or rigs) measured
        at or after ``since``, oldest first: a rollout's health gate inputs."""
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
            select(*cols)
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
        return self._runner.run(lambda s: [GateReport(**row._asdict()) for row in s.execute(stmt)])

    def health_report_count(self) -> int:
        return self._runner.run(
            lambda s: int(s.scalar(select(func.count()).select_from(HealthReportRow)) or 0)
        )
