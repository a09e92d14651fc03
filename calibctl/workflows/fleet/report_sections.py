"""``calibctl report SERIAL``'s sections from the rooms above the report's: the ``calibctl diff`` against the
previous accepted version (has it really changed?) and, when robots reported on the serial, its ``fleet
trends``.
The report room draws them (``ReportData.diff``, ``.trends``); this room, which may read both, fills them."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from calibctl.config import Settings
from calibctl.errors import CalibctlError, NotFoundError
from calibctl.workflows.compare.diff import DiffRequest, diff_cameras
from calibctl.workflows.fleet import health
from calibctl.workflows.report import report
from calibctl.workflows.report.report_data import DiffSection, ReportData
from calibctl.workflows.store_admin import records


def _previous_accepted(settings: Settings, serial: str, version: int) -> int | None:
    with records.open_store(settings) as store:
        earlier = [
            a.version for a in store.list_artifacts(serial) if a.status == "accepted" and a.version < version
        ]
    return max(earlier, default=None)


def extend(settings: Settings, data: ReportData) -> ReportData:
    """``data`` with the diff section (or why there is none) and the trends section (when reports exist)."""
    art = data.artifact
    diff, note = None, None
    previous = _previous_accepted(settings, art.serial, art.version)
    if previous is None:
        note = f"no accepted version of {art.serial} before @{art.version} to compare with"
    else:
        try:
            d = diff_cameras(settings, DiffRequest(f"{art.serial}@{previous}", art.ref))
            r = d.result
            sigma = None if r.raw.sigma_px is None else float(np.median(r.raw.sigma_px))
            diff = DiffSection(
                f"{art.serial}@{previous}",
                d.verdict,
                r.raw.percentiles_px,
                r.fit.percentiles_px,
                r.rotation_fit_deg,
                sigma,
                tuple(r.reasons),
            )
        except CalibctlError as exc:  # two image sizes, a damaged covariance: say what could not be compared
            note = f"{art.serial}@{previous} and {art.ref} were not compared: {exc.message}"
    try:
        trends = health.trends(settings, art.serial).as_json()
    except NotFoundError:
        trends = None  # no robot reported on it: no section
    return dataclasses.replace(data, diff=diff, diff_note=note, trends=trends)


def write_report(settings: Settings, ref: str, out: Path | None, *, force: bool) -> tuple[Path, ReportData]:
    """``calibctl report SERIAL[@N]``: the report page with the diff and trends sections."""
    return report.write_report(settings, ref, out, force=force, extend=lambda data: extend(settings, data))
