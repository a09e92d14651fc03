"""A calibration change rolled out like a deploy (seed chapter 6, prompt A point 6): canary, health gate,
promote or roll back the fleet in one command.

``start``: new versions for a set of serials and a canary cohort; the canary robots' assignments are written
with the rollout, in one transaction; each target is diffed against the version its robot ran (``calibctl
diff``), so the operator sees whether the change is beyond re-calibration noise. ``promote``: the health gate, then every other robot carrying a target
serial gets its new version, in one transaction. ``rollback``: every robot the rollout touched is put back on
the version it ran before, in one transaction. Each is appended with a compare-and-set on the log's length,
so a step decided on a stale fleet writes nothing.

The health gate (this first step): every (canary robot, target serial) must have at least one stored
``calibctl check`` of serial@new version since the rollout started, and all of them must pass. No report
yet: exit 2, nothing promoted; a failing one: exit 1, the rollout is held (roll it back).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from calibctl.artifacts.common import utc_now
from calibctl.artifacts.fleet import FleetEvent
from calibctl.config import Settings
from calibctl.errors import CalibctlError, NotFoundError, UsageError, VerdictFailed
from calibctl.workflows.compare.diff import DiffRequest, diff_cameras
from calibctl.workflows.fleet.robots import FleetStatus, check_reason, fleet_event, status
from calibctl.workflows.store_admin import records


@dataclass
class Rollout:
    """A rollout replayed from the log: its event, per robot its state, and whether it is open."""

    start: FleetEvent
    diffs: dict[str, dict[str, Any]] = field(default_factory=dict)  # rollout start: target serial -> its diff
    # robot -> pending, canary (no health report yet), healthy, failed, promoted, rolled back, untouched
    state: dict[str, str] = field(default_factory=dict)
    closed: str | None = None  # "promoted" or "rolled back"

    @property
    def name(self) -> str:
        return self.start.subject

    def as_json(self) -> dict[str, Any]:
        out = {"rollout": self.name, "targets": self.start.targets, "canary": self.start.canary,
               "closed": self.closed, "robots": self.state}
        return {**out, "diffs": self.diffs} if self.diffs else out


@dataclass
class Fleet:
    """The log replayed: robots' serials, what each robot runs, rollouts, and the log's length."""

    carries: dict[str, list[str]]
    running: dict[tuple[str, str], int]
    rollouts: dict[str, Rollout]
    history: dict[tuple[str, str], list[tuple[int, str | None]]]  # (robot, serial) -> [(version, rollout)]
    length: int


def replay(events: list[FleetEvent]) -> Fleet:
    fleet = Fleet({}, {}, {}, {}, len(events))
    for e in events:
        if e.kind == "register":
            fleet.carries[e.subject] = list(e.serials)
        elif e.kind == "assign" and e.serial is not None and e.version is not None:
            fleet.running[(e.subject, e.serial)] = e.version
            fleet.history.setdefault((e.subject, e.serial), []).append((e.version, e.rollout))
        elif e.kind == "rollout":
            fleet.rollouts[e.subject] = Rollout(e)
        elif e.kind in ("promote", "rollback"):
            fleet.rollouts[e.subject].closed = "promoted" if e.kind == "promote" else "rolled back"
    for r in fleet.rollouts.values():
        for robot, serials in fleet.carries.items():
            touched = [s for s in serials if s in r.start.targets]
            if not touched:
                continue
            assigned = any(ro == r.name for s in touched for _, ro in fleet.history.get((robot, s), []))
            if r.closed == "rolled back":
                r.state[robot] = "rolled back" if assigned else "untouched"
            elif not assigned:
                r.state[robot] = "pending"
            elif robot in r.start.canary:
                r.state[robot] = "healthy" if r.closed == "promoted" else "canary"
            else:
                r.state[robot] = "promoted"
    return fleet


def _read(settings: Settings) -> tuple[Fleet, dict[str, list]]:
    with records.open_store(settings) as store:
        events = store.fleet_events()
        fleet = replay(events)
        serials = {s for r in fleet.rollouts.values() for s in r.start.targets}
        checks = {s: store.checks(s) for s in sorted(serials)}
    return fleet, checks


def _append(settings: Settings, events: list[FleetEvent], after: int) -> None:
    with records.open_store(settings, write=True) as store:
        store.append_fleet_events(events, after)


def _new(kind: str, settings: Settings, reason: str, **fields: Any) -> FleetEvent:
    return fleet_event(kind=kind, actor=settings.operator, station=settings.station, at=utc_now(), reason=reason, **fields)


def start(settings: Settings, name: str, targets: list[str], canary: list[str], reason: str) -> Rollout:
    """Start rollout ``name``: ``targets`` SERIAL@N each, ``canary`` robots get theirs now."""
    check_reason(reason)
    wanted: dict[str, int] = {}
    for ref in targets:
        serial, version = records.parse_artifact_ref(ref)
        if version is None:
            raise UsageError(f"target '{ref}' names no version", f"e.g. {serial}@4")
        if serial in wanted:
            raise UsageError(f"{serial} is targeted twice")
        wanted[serial] = version
    fleet, _ = _read(settings)
    busy = {robot: r.name for r in fleet.rollouts.values() if r.closed is None for robot in r.start.canary}
    for robot in canary:
        if robot in busy:
            raise UsageError(f"robot {robot} is already in the canary cohort of open rollout {busy[robot]}",
                             f"promote or roll back {busy[robot]} first")
        if robot in fleet.carries and not set(fleet.carries[robot]) & set(wanted):
            raise UsageError(f"canary robot {robot} carries none of the target serials")
    head = _new("rollout", settings, reason, rollout=name, targets=wanted, canary=canary)
    assigns = [_new("assign", settings, f"canary of rollout {name}", robot=robot, serial=s, version=wanted[s], rollout=name)
               for robot in canary for s in fleet.carries.get(robot, []) if s in wanted]
    _append(settings, [head, *assigns], fleet.length)
    rollout = replay_after(settings, name)
    rollout.diffs = _diffs(settings, fleet, wanted)
    return rollout


def _diffs(settings: Settings, fleet: Fleet, wanted: dict[str, int]) -> dict[str, dict[str, Any]]:
    """Each target against the version its robot ran before (``calibctl diff``): is the change beyond noise?"""
    out: dict[str, dict[str, Any]] = {}
    before = {serial: version for (_, serial), version in fleet.running.items()}
    for serial, version in sorted(wanted.items()):
        old = before.get(serial)
        if old is None or old == version:
            continue
        try:
            d = diff_cameras(settings, DiffRequest(f"{serial}@{old}", f"{serial}@{version}"))
        except CalibctlError as exc:
            out[serial] = {"from": old, "verdict": "not compared", "why": exc.message}
            continue
        out[serial] = {"from": old, "verdict": d.verdict, "p50_px": d.result.raw.percentiles_px["p50"],
                       "max_px": d.result.raw.percentiles_px["max"]}
    return out


def replay_after(settings: Settings, name: str) -> Rollout:
    fleet, checks = _read(settings)
    if name not in fleet.rollouts:
        raise NotFoundError(f"no rollout {name}", "`calibctl fleet status` lists the rollouts")
    rollout = fleet.rollouts[name]
    if rollout.closed is None:
        for robot, state in list(rollout.state.items()):
            if state == "canary":
                rollout.state[robot] = _health(rollout, fleet, robot, checks)
    return rollout


def _health(rollout: Rollout, fleet: Fleet, robot: str, checks: dict[str, list]) -> str:
    """canary (no report yet), healthy (every target serial checked since the start, all passed) or failed."""
    verdicts = []
    for serial in fleet.carries.get(robot, []):
        version = rollout.start.targets.get(serial)
        if version is None:
            continue
        seen = [c.passed for c in checks.get(serial, []) if c.version == version and c.at >= rollout.start.at]
        verdicts.append(None if not seen else all(seen))
    if any(v is False for v in verdicts):
        return "failed"
    return "healthy" if verdicts and all(v is True for v in verdicts) else "canary"


def promote(settings: Settings, name: str, reason: str) -> Rollout:
    """The health gate, then every other robot carrying a target serial gets its version (one transaction)."""
    check_reason(reason)
    rollout = replay_after(settings, name)
    if rollout.closed is not None:
        raise UsageError(f"rollout {name} is {rollout.closed} already")
    canary = {r: s for r, s in rollout.state.items() if r in rollout.start.canary}
    failed = sorted(r for r, s in canary.items() if s == "failed")
    if failed:
        raise VerdictFailed(f"rollout {name} is held: canary robot(s) {', '.join(failed)} report failing checks; "
                            "nothing promoted", f"roll it back: calibctl fleet rollout rollback {name} --reason ...")
    waiting = sorted(r for r, s in canary.items() if s == "canary")
    if waiting or not canary:
        raise UsageError(f"rollout {name} cannot be promoted: canary robot(s) {', '.join(waiting) or '(none)'} have "
                         "no health report yet (a `calibctl check` of the new version); nothing promoted",
                         "check the canary robots' cameras, then promote again")
    fleet, _ = _read(settings)
    assigns = [_new("assign", settings, f"promoted by rollout {name}", robot=robot, serial=s,
                    version=rollout.start.targets[s], rollout=name)
               for robot, state in sorted(rollout.state.items()) if state == "pending"
               for s in fleet.carries[robot] if s in rollout.start.targets]
    _append(settings, [*assigns, _new("promote", settings, reason, rollout=name)], fleet.length)
    return replay_after(settings, name)


def rollback(settings: Settings, name: str, reason: str) -> Rollout:
    """Every robot the rollout assigned goes back to the version it ran before (one transaction); robots that
    ran nothing before keep the record of the rollout's version and are listed as rolled back."""
    check_reason(reason)
    fleet, _ = _read(settings)
    if name not in fleet.rollouts:
        raise NotFoundError(f"no rollout {name}", "`calibctl fleet status` lists the rollouts")
    if fleet.rollouts[name].closed == "rolled back":
        raise UsageError(f"rollout {name} is rolled back already")
    assigns = []
    for (robot, serial), steps in sorted(fleet.history.items()):
        mine = [i for i, (_, ro) in enumerate(steps) if ro == name]
        if mine and mine[0] > 0:
            previous = steps[mine[0] - 1][0]
            if fleet.running[(robot, serial)] != previous:
                assigns.append(_new("assign", settings, f"rolled back by rollout {name}", robot=robot, serial=serial,
                                    version=previous, rollout=name))
    _append(settings, [*assigns, _new("rollback", settings, reason, rollout=name)], fleet.length)
    return replay_after(settings, name)


def fleet_status(settings: Settings) -> tuple[FleetStatus, list[Rollout]]:
    """``calibctl fleet status``: the robots (``robots.status``) and every rollout with each robot's state."""
    robots_now = status(settings)
    fleet, _ = _read(settings)
    return robots_now, [replay_after(settings, name) for name in fleet.rollouts]
