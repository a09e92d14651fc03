"""The fleet's log replayed: which robot carries which serials and rigs, the version each runs, every rollout.

A target is ``("serial", SERIAL)`` or ``("rig", RIG)``: robots carry both, rollouts roll out both, and a serial
and a rig may share a name without meeting.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from calibctl.artifacts.fleet import FleetEvent, GateEvidence, TargetDiff

Target = tuple[str, str]


def label(t: Target) -> str:
    """How a target is written: CAM-1, rig R1."""
    return t[1] if t[0] == "serial" else f"rig {t[1]}"


def ref(t: Target, version: int) -> str:
    """How a target@version is written: CAM-1@2, rig R1@2."""
    return f"{label(t)}@{version}"


@dataclass
class Rollout:
    """A rollout replayed from the log: its event, per robot its state, and whether it is open."""

    start: FleetEvent
    # robot -> pending, canary (no health report yet), healthy, failed, promoted, rolled back, untouched
    state: dict[str, str] = field(default_factory=dict)
    closed: str | None = None  # "promoted" or "rolled back"
    promote: FleetEvent | None = None  # its promote event: the gate inputs and diffs it recorded
    evidence: list[GateEvidence] = field(default_factory=list)  # open: the gate inputs read so far
    waiting: dict[str, list[str]] = field(default_factory=dict)  # open: canary robot -> targets with no report
    failing: dict[str, list[str]] = field(default_factory=dict)  # open: canary robot -> its failing inputs

    @property
    def name(self) -> str:
        return self.start.subject

    @property
    def diffs(self) -> dict[Target, TargetDiff]:
        """Each target's diff against the version its robots ran, as the rollout event recorded it."""
        return {**{("serial", s): d for s, d in self.start.diffs.items()},
                **{("rig", r): d for r, d in self.start.rig_diffs.items()}}

    @property
    def targets(self) -> dict[Target, int]:
        return {**{("serial", s): v for s, v in self.start.targets.items()},
                **{("rig", r): v for r, v in self.start.rig_targets.items()}}

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"rollout": self.name, "targets": self.start.targets, "rig_targets": self.start.rig_targets,
                               "canary": self.start.canary, "closed": self.closed, "robots": self.state}
        if self.diffs:
            out["diffs"] = {label(t): d.model_dump(mode="json") for t, d in self.diffs.items()}
        if self.promote is not None:
            out["gate"] = [e.model_dump(mode="json") for e in self.promote.gate]
        if self.waiting or self.failing:
            out["waiting"], out["failing"] = self.waiting, self.failing
        return out


@dataclass
class Fleet:
    """The log replayed: robots' targets, what each robot runs, rollouts, and the log's length."""

    carries: dict[str, list[Target]]
    running: dict[tuple[str, Target], int]
    rollouts: dict[str, Rollout]
    history: dict[tuple[str, Target], list[tuple[int, str | None]]]  # (robot, target) -> [(version, rollout)]
    length: int


def replay(events: list[FleetEvent]) -> Fleet:
    fleet = Fleet({}, {}, {}, {}, len(events))
    for e in events:
        if e.kind == "register":
            fleet.carries[e.subject] = [*(("serial", s) for s in e.serials), *(("rig", r) for r in e.rigs)]
        elif e.kind == "assign" and e.version is not None:
            fleet.running[(e.subject, e.target)] = e.version
            fleet.history.setdefault((e.subject, e.target), []).append((e.version, e.rollout))
        elif e.kind == "rollout":
            fleet.rollouts[e.subject] = Rollout(e)
        elif e.kind in ("promote", "rollback"):
            fleet.rollouts[e.subject].closed = "promoted" if e.kind == "promote" else "rolled back"
            if e.kind == "promote":
                fleet.rollouts[e.subject].promote = e
    for r in fleet.rollouts.values():
        targets = r.targets
        for robot, carried in fleet.carries.items():
            touched = [t for t in carried if t in targets]
            if not touched:
                continue
            assigned = any(ro == r.name for t in touched for _, ro in fleet.history.get((robot, t), []))
            if r.closed == "rolled back":
                r.state[robot] = "rolled back" if assigned else "untouched"
            elif not assigned:
                r.state[robot] = "pending"
            elif robot in r.start.canary:
                r.state[robot] = "healthy" if r.closed == "promoted" or r.promote is not None else "canary"
            else:
                r.state[robot] = "promoted"
    return fleet
