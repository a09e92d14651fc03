"""Robots' health reports in the store (revision 0011_health_reports_health25): ``HealthReportRow``.

Telemetry, not records: append-only (the migration's triggers refuse UPDATE and DELETE) and each row keeps the
report's canonical JSON with its sha256, but the rows are not hash-chained (docs/fleet.md says why). A batch is
written all or nothing; before it is, every report is checked against what it refers to: its robot is registered
and carries its serial, and its ``source_id`` is new (in the store and in the batch).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import func, insert, select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.artifacts.health import HealthReport
from calibctl.store import codec
from calibctl.store.fleet import _registration
from calibctl.store.models import HealthReportRow

_CHUNK = 500  # source ids per IN (...) query: under SQLite's bound-parameter limit
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


def _problems(s: Session, reports: Sequence[HealthReport]) -> list[tuple[int, str]]:
    """(index in ``reports``, why) for each report that refers to something wrong; empty when all may be stored."""
    carried: dict[str, set[str] | None] = {}
    for robot in {r.robot for r in reports}:
        registered = _registration(s, robot)
        carried[robot] = None if registered is None else set(registered.serials)
    ids = [r.source_id for r in reports]
    stored: set[str] = set()
    for i in range(0, len(ids), _CHUNK):
        stored.update(s.scalars(select(HealthReportRow.source_id).where(HealthReportRow.source_id.in_(ids[i:i + _CHUNK]))))
    seen: set[str] = set()
    out = []
    for i, r in enumerate(reports):
        serials = carried[r.robot]
        if serials is None:
            out.append((i, f"robot {r.robot} is not registered"))
        elif r.serial not in serials:
            out.append((i, f"unknown serial {r.serial}: robot {r.robot} carries {', '.join(sorted(serials)) or 'none'}"))
        elif r.source_id in stored:
            out.append((i, f"duplicate report: source id {r.source_id} is stored already"))
        elif r.source_id in seen:
            out.append((i, f"duplicate report: source id {r.source_id} appears twice in this batch"))
        seen.add(r.source_id)
    return out


class HealthStoreMixin:
    """Health-report methods of ``Store`` (which provides ``_run``)."""

    _run: Callable[..., Any]

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
                rows.append({"source_id": r.source_id, "serial": r.serial, "robot": r.robot, "kind": r.kind, "at": r.time,
                             **{n: getattr(r, n) for n in NUMBERS}, "ingested_at": now, "payload": payload,
                             "payload_sha256": sha256_hex(payload.encode("utf-8"))})
            s.execute(insert(HealthReportRow), rows)
            return []

        return self._run(work, write=True)

    def health_rows(self, serial: str) -> list[HealthRow]:
        """Every stored report on ``serial``, oldest first."""
        cols = [getattr(HealthReportRow, n) for n in ("serial", "kind", "at", *NUMBERS)]
        return self._run(lambda s: [HealthRow(*row) for row in s.execute(
            select(*cols).where(HealthReportRow.serial == serial).order_by(HealthReportRow.at, HealthReportRow.id))])

    def fleet_check_rms(self) -> dict[str, tuple[float, int]]:
        """Serial -> (mean check RMS px, number of check reports), over every serial with check reports."""
        stmt = (select(HealthReportRow.serial, func.avg(HealthReportRow.rms_px), func.count())
                .where(HealthReportRow.kind == "check").group_by(HealthReportRow.serial))
        return self._run(lambda s: {str(serial): (float(mean), int(n)) for serial, mean, n in s.execute(stmt)})

    def health_report_count(self) -> int:
        return self._run(lambda s: int(s.scalar(select(func.count()).select_from(HealthReportRow)) or 0))
