"""The rig version an evidence edge was stored as (``handeye --rig``, ``lidar solve --rig``), as both
commands render it: the ``stored`` block of their JSON and the human line."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import typer

from calibctl.artifacts.rig import RigCalibration
from calibctl.cli.render import emit_json, say
from calibctl.errors import EXIT_VERDICT_FAIL


def stored_summary(stored: RigCalibration) -> dict[str, Any]:
    """The ``stored`` block of a command's JSON: the rig version an evidence edge was written as."""
    return {
        "rig": stored.rig,
        "version": stored.version,
        "status": stored.status,
        "active": stored.status == "accepted",
        "content_sha256": stored.content_sha256,
    }


def finish_solve(
    doc: dict[str, Any],
    as_json: bool,
    render: Callable[[dict[str, Any]], None],
    accepted: bool,
    stored: RigCalibration | None,
    written: list[str],
) -> None:
    """How a sensor-edge solve command ends (``lidar solve``, ``imu solve``): the ``stored`` block added,
    the document printed (``--json``) or rendered with the files written and the version stored, and
    exit 1 when the result, or the version it was stored as, was rejected."""
    lines = list(written)
    if stored is not None:
        doc["stored"] = stored_summary(stored)
        lines.append(stored_line(stored))
    if as_json:
        emit_json(doc)
    else:
        render(doc)
        for line in lines:
            say(line)
    if not accepted or (stored is not None and stored.status != "accepted"):
        raise typer.Exit(EXIT_VERDICT_FAIL)


def stored_line(stored: RigCalibration) -> str:
    """The human line for the same."""
    return f"stored as rig {stored.rig}@{stored.version} " + (
        "(active)" if stored.status == "accepted" else "(rejected, never active; no edge)"
    )
