"""One evidence edge of a stored rig version as a file: its result document or /tf_static YAML."""

from __future__ import annotations

from collections.abc import Mapping

from calibctl.artifacts.handeye import RosFrames
from calibctl.artifacts.rig import RigCalibration
from calibctl.errors import NotFoundError, UsageError
from calibctl.workflows.edges.kinds import KINDS, evidence_of, kind_of


def edge_export(cal: RigCalibration, edge: str, fmt: str, frames: Mapping[str, str] | None = None) -> str:
    """One evidence edge of a stored version, ``FROM:TO``: its result document (json, with ``ros_frames``
    from ``frames``) or /tf_static (tf, its frames renamed by ``frames``: the rig export's robot frame
    names)."""
    parent, sep, child = edge.partition(":")
    if not sep or not parent or not child:
        raise UsageError(f"--edge must be FROM:TO, got {edge!r}")
    evidence = evidence_of(cal)
    found = next((h for h in evidence if (h.parent_frame, h.child_frame) == (parent, child)), None)
    if found is None:
        have = ", ".join(f"{h.parent_frame}:{h.child_frame}" for h in evidence) or "none"
        raise NotFoundError(
            f"rig {cal.rig}@{cal.version} has no {_kinds_text()} edge {parent} -> {child} (it has: {have})",
            hint=f"see `calibctl rig show {cal.rig}@{cal.version}`",
        )
    if fmt == "json":  # named as the robot's files name them too; the document's own frames stay
        if frames is not None:
            named = RosFrames(parent_frame=frames.get(parent, parent), child_frame=frames.get(child, child))
            found = found.model_copy(update={"ros_frames": named})
        return found.model_dump_json(indent=2) + "\n"
    if fmt != "tf":
        raise UsageError(f"--edge exports json or tf, not {fmt}")
    return kind_of(found).tf(found, cal, frames)


def _kinds_text() -> str:
    words = [k.label for k in KINDS]
    return " or ".join(words) if len(words) < 3 else ", ".join(words[:-1]) + " or " + words[-1]
