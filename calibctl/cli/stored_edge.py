"""The rig version an evidence edge was stored as (``handeye --rig``, ``lidar solve --rig``), as both
commands render it: the ``stored`` block of their JSON and the human line."""

from __future__ import annotations

from typing import Any

from calibctl.artifacts.rig import RigCalibration


def stored_summary(stored: RigCalibration) -> dict[str, Any]:
    """The ``stored`` block of a command's JSON: the rig version an evidence edge was written as."""
    return {
        "rig": stored.rig,
        "version": stored.version,
        "status": stored.status,
        "active": stored.status == "accepted",
        "content_sha256": stored.content_sha256,
    }


def stored_line(stored: RigCalibration) -> str:
    """The human line for the same."""
    return f"stored as rig {stored.rig}@{stored.version} " + (
        "(active)" if stored.status == "accepted" else "(rejected, never active; no edge)"
    )
