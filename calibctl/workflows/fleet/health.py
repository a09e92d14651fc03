"""``calibctl fleet ingest | trends``: the health reports robots send, and their trends per serial.

Ingest reads JSON-lines files (one ``HealthReport`` per line), all or nothing per file: a file with one
refused line (malformed, from the future, for a serial its robot does not carry, a duplicate source id) writes
nothing and names each refused line; the other files are still ingested. Trends are conditionals, not
aggregates (seed chapter 4 and chapter 6's modes): RMS against temperature, time offset against time in ppm,
and this camera's RMS against the rest of the fleet's cameras, each with its n and sigma.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import timedelta
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from calibctl import bounded
from calibctl.artifacts.common import validation_message
from calibctl.artifacts.health import HealthReport
from calibctl.config import Settings
from calibctl.errors import InputError
from calibctl.workflows.fleet.trends import Trends, compute_trends
from calibctl.workflows.store_admin import records

MAX_LINE_CHARS = 4096
"""A report is a few hundred characters; a longer line is not one."""
SPREAD_WINDOW = timedelta(days=30)
"""The per-camera spread compares the serials' check RMS over the 30 days up to this serial's newest report:
the
cameras as they are now (a camera repaired in spring is not the worst all year), and a bounded read at fleet
size."""
MAX_LINES = 200_000
"""Reports per file: a year of daily reports of 500 robots' sensors is 730k, sent as several files."""


@dataclass
class FileResult:
    """One ingested file: how many reports were stored and, when refused, why per line (1-based)."""

    path: str
    stored: int = 0
    refused: list[tuple[int, str]] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "stored": self.stored,
            "refused": [{"line": n, "why": why} for n, why in self.refused],
        }


def _parse(path: Path) -> tuple[list[HealthReport], list[int], list[tuple[int, str]]]:
    """The reports of ``path``, the line number of each, and (line, why) of each line that is not a report."""
    text = bounded.read_text(path, "ingest")
    reports: list[HealthReport] = []
    line_numbers: list[int] = []
    bad: list[tuple[int, str]] = []
    lines = text.splitlines()
    if len(lines) > MAX_LINES:
        raise InputError(
            f"{path}: {len(lines)} lines, more than {MAX_LINES} reports in one file",
            "split it into files of at most 200000 lines",
        )
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        if len(line) > MAX_LINE_CHARS:
            bad.append((number, f"{len(line)} characters, longer than a report ({MAX_LINE_CHARS})"))
            continue
        try:
            data = bounded.parse_json(line, f"{path}:{number}")
            reports.append(HealthReport.model_validate(data))
            line_numbers.append(number)
        except InputError as exc:
            bad.append((number, exc.message))
        except ValidationError as exc:
            bad.append((number, validation_message(exc, "the report")))
    return reports, line_numbers, bad


def ingest(settings: Settings, paths: list[Path]) -> list[FileResult]:
    """Store the reports of each file in one transaction per file (all or nothing per file)."""
    results = []
    with records.open_store(settings, write=True) as store:
        for path in paths:
            reports, line_numbers, bad = _parse(path)
            result = FileResult(str(path))
            if not bad:
                bad = [(line_numbers[i], why) for i, why in store.add_health_reports(reports)]
            if bad:
                result.refused = sorted(bad)
            else:
                result.stored = len(reports)
            results.append(result)
    return results


def trends(settings: Settings, serial: str) -> Trends:
    """``serial``'s trends from its stored reports, and its RMS against every other serial's (NotFoundError:
    none)."""
    with records.open_store(settings) as store:
        rows = store.health_rows(serial)  # oldest first
        fleet = store.fleet_check_rms(rows[-1].at - SPREAD_WINDOW) if rows else {}
    t = compute_trends(serial, rows, fleet)
    if t.fleet is not None:
        t.fleet["window_days"] = SPREAD_WINDOW.days
    return t
