"""The fleet's log replayed: which robot carries which serials and rigs, the version each runs, every rollout.

A target is ``("serial", SERIAL)`` or ``("rig", RIG)``: robots carry both, rollouts roll out both, and a
serial and a rig may share a name without meeting.

The replay is incremental (``Fleet.apply`` one event at a time, ``Fleet.settle`` the rollouts' robot states at
the end), and its state up to event N is plain JSON (``to_state``, ``from_state``): the fleet checkpoints
(``fleet_checkpoints``) are that state, so a read replays only the events after the newest one. It lives in
the store layer because ``db verify`` re-derives each checkpoint from the log.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
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
    waiting: dict[str, list[str]] = field(
        default_factory=dict
    )  # open: canary robot -> targets with no report
    failing: dict[str, list[str]] = field(default_factory=dict)  # open: canary robot -> its failing inputs

    @property
    def name(self) -> str:
        return self.start.subject

    @property
    def diffs(self) -> dict[Target, TargetDiff]:
        """Each target's diff against the version its robots ran, as the rollout event recorded it."""
        return {
            **{("serial", s): d for s, d in self.start.diffs.items()},
            **{("rig", r): d for r, d in self.start.rig_diffs.items()},
        }

    @property
    def targets(self) -> dict[Target, int]:
        return {
            **{("serial", s): v for s, v in self.start.targets.items()},
            **{("rig", r): v for r, v in self.start.rig_targets.items()},
        }

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "rollout": self.name,
            "targets": self.start.targets,
            "rig_targets": self.start.rig_targets,
            "canary": self.start.canary,
            "closed": self.closed,
            "robots": self.state,
        }
        if self.diffs:
            out["diffs"] = {label(t): d.model_dump(mode="json") for t, d in self.diffs.items()}
        if self.promote is not None:
            out["gate"] = [e.model_dump(mode="json") for e in self.promote.gate]
        if self.waiting or self.failing:
            out["waiting"], out["failing"] = self.waiting, self.failing
        return out


@dataclass
class Fleet:
    """The log replayed up to event ``length``: robots' targets, what each robot runs, rollouts.

    ``found`` is the compact history of each (robot, target) that was ever assigned: per rollout that assigned
    it, the version it ran just before that rollout's first assignment (None: nothing before). That is all a
    rollback (what to put back) and a rollout's robot states (was it assigned) read, and it does not grow with
    re-assignments.
    """

    carries: dict[str, list[Target]] = field(default_factory=dict)
    running: dict[tuple[str, Target], int] = field(default_factory=dict)
    rollouts: dict[str, Rollout] = field(default_factory=dict)
    found: dict[tuple[str, Target], dict[str, int | None]] = field(default_factory=dict)
    length: int = 0
    registered_at: dict[str, str] = field(
        default_factory=dict
    )  # robot -> its register event's time, ISO 8601
    positions: dict[str, tuple[int, int | None]] = field(
        default_factory=dict
    )  # rollout -> (start, promote) events

    def apply(self, e: FleetEvent) -> None:
        """Event ``length + 1`` of the log."""
        self.length += 1
        if e.kind == "register":
            self.carries[e.subject] = [*(("serial", s) for s in e.serials), *(("rig", r) for r in e.rigs)]
            self.registered_at[e.subject] = e.at.isoformat()
        elif e.kind == "assign" and e.version is not None:
            key = (e.subject, e.target)
            found = self.found.setdefault(key, {})
            if e.rollout is not None and e.rollout not in found:
                found[e.rollout] = self.running.get(key)
            self.running[key] = e.version
        elif e.kind == "rollout":
            self.rollouts[e.subject] = Rollout(e)
            self.positions[e.subject] = (self.length, None)
        elif e.kind in ("promote", "rollback"):
            self.rollouts[e.subject].closed = "promoted" if e.kind == "promote" else "rolled back"
            if e.kind == "promote":
                self.rollouts[e.subject].promote = e
                self.positions[e.subject] = (self.positions[e.subject][0], self.length)

    def settle(self) -> Fleet:
        """Each rollout's robot states from the replayed log (before any health gate is read)."""
        for r in self.rollouts.values():
            r.state = {}
            targets = r.targets
            for robot, carried in self.carries.items():
                touched = [t for t in carried if t in targets]
                if not touched:
                    continue
                assigned = any(r.name in self.found.get((robot, t), {}) for t in touched)
                if r.closed == "rolled back":
                    r.state[robot] = "rolled back" if assigned else "untouched"
                elif not assigned:
                    r.state[robot] = "pending"
                elif robot in r.start.canary:
                    r.state[robot] = (
                        "healthy" if r.closed == "promoted" or r.promote is not None else "canary"
                    )
                else:
                    r.state[robot] = "promoted"
        return self


def replay(events: list[FleetEvent], base: Fleet | None = None) -> Fleet:
    """``base`` (default: the empty log) with ``events`` applied after it, settled."""
    fleet = base or Fleet()
    for e in events:
        fleet.apply(e)
    return fleet.settle()


STATE_FORMAT = 1
"""Bumped when ``to_state``'s shape changes: a checkpoint of another format is ignored (and rewritten)."""


def to_state(fleet: Fleet) -> dict[str, Any]:
    """The replayed log as plain JSON (insertion order kept: it is the order status lists robots and rollouts
    in). Rollouts are named by the positions of their start and promote events, which are read back from the
    log."""
    return {
        "format": STATE_FORMAT,
        "length": fleet.length,
        "robots": [
            [robot, fleet.registered_at[robot], [list(t) for t in carried]]
            for robot, carried in fleet.carries.items()
        ],
        "running": [[robot, t[0], t[1], v] for (robot, t), v in fleet.running.items()],
        "found": [[robot, t[0], t[1], found] for (robot, t), found in fleet.found.items()],
        "rollouts": [[name, r.closed, *fleet.positions[name]] for name, r in fleet.rollouts.items()],
    }


def rollout_positions(state: dict[str, Any]) -> list[int]:
    """The log positions of the rollout and promote events a state refers to."""
    return [p for _, _, start, promote in state["rollouts"] for p in (start, promote) if p is not None]


def from_state(state: dict[str, Any], events: dict[int, FleetEvent] | None) -> Fleet:
    """``to_state``'s inverse (not settled); ``events``: the events at ``rollout_positions(state)``; None:
    each rollout holds a stand-in event that names it and nothing else (enough to apply more events and take
    ``to_state`` again, what the checkpoint writer does, without decoding every rollout with its diffs).
    KeyError, TypeError or ValueError when the state is not of this shape."""
    if state["format"] != STATE_FORMAT:
        raise ValueError(f"state format {state['format']}, not {STATE_FORMAT}")
    fleet = Fleet(length=int(state["length"]))
    for robot, at, carried in state["robots"]:
        fleet.carries[robot] = [(str(kind), str(name)) for kind, name in carried]
        fleet.registered_at[robot] = str(at)
    fleet.running = {(robot, (kind, name)): int(v) for robot, kind, name, v in state["running"]}
    fleet.found = {(robot, (kind, name)): dict(found) for robot, kind, name, found in state["found"]}
    for name, closed, start, promote in state["rollouts"]:
        if events is None:  # the writer's stand-in: no validation, never settled nor shown
            stand_in = FleetEvent.model_construct(
                kind="rollout", rollout=str(name), actor="", station="", reason="", at=datetime.min
            )
            r = Rollout(stand_in, closed=closed)
        else:
            r = Rollout(events[start], closed=closed, promote=None if promote is None else events[promote])
            if (
                r.name != name
                or r.start.kind != "rollout"
                or (r.promote is not None and r.promote.kind != "promote")
            ):
                raise ValueError(
                    f"rollout {name}: the events at {start}, {promote} are not its start and promote"
                )
        fleet.rollouts[name], fleet.positions[name] = r, (start, promote)
    return fleet
