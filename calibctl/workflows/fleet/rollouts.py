"""A calibration change rolled out like a deploy (seed chapter 6, prompt A point 6): canary, health gate,
promote or roll back the fleet in one command.

``start``: new versions for a set of serials and rigs and a canary cohort; the canary robots' assignments are
written with the rollout, in one transaction; each target is diffed against the version its robots ran
(``calibctl diff``, recorded in the rollout event), so the operator sees whether the change is beyond
re-calibration noise. ``promote``: the health gate (``gate``: the canary robots' checks and health reports
since the start), then every other robot carrying a target gets its new version and each rig target becomes
its rig's active version, in one transaction; the promote event records the gate's inputs. ``rollback``: every
robot the rollout touched is put back on the version it ran before and each rig the promote activated gets its
previous active version back, in one transaction. Each is appended with a compare-and-set on the log's length
(and on each rig's active version), so a step decided on a stale fleet writes nothing.

No gate input yet for a canary target: exit 2, nothing promoted; a failing one: exit 1, the rollout is held
(roll it back).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from calibctl.artifacts.fleet import FleetEvent
from calibctl.config import Settings
from calibctl.errors import NotFoundError, UsageError, VerdictFailed
from calibctl.store.fleet import RigActivationStep
from calibctl.store.fleet_ledger import Fleet, Rollout, Target, label, ref
from calibctl.workflows.fleet.gate import read_gate, target_diffs
from calibctl.workflows.fleet.robots import FleetStatus, check_reason, new_fleet_event, robot_states
from calibctl.workflows.store_admin import records

if TYPE_CHECKING:
    from calibctl.store.repository import Store


def _read(settings: Settings, name: str | None = None) -> tuple[Fleet, dict[str, int]]:
    """The fleet replayed, each open rollout's canary states read from its gate (``name``: that rollout only,
    NotFoundError when there is none), and the rigs' active versions."""
    with records.open_store(settings) as store:
        fleet = store.fleet().fleet
        if name is not None and name not in fleet.rollouts:
            raise NotFoundError(f"no rollout {name}", "`calibctl fleet status` lists the rollouts")
        _gated(store, fleet, name)
        _, rig_active = store.active_versions()
    return fleet, rig_active


def _gated(store: Store, fleet: Fleet, name: str | None = None) -> None:
    """Each open rollout's (``name``: that one's) canary robots' states from its health gate's inputs."""
    for r in fleet.rollouts.values():
        if r.closed is None and name in (None, r.name):
            gate = read_gate(store, r, fleet)
            r.evidence, r.waiting, r.failing = gate.evidence, gate.waiting, gate.failing
            r.state.update({robot: gate.state(robot) for robot, st in r.state.items() if st == "canary"})


def _append(
    settings: Settings, events: list[FleetEvent], after: int, rig_steps: Sequence[RigActivationStep] = ()
) -> None:
    with records.open_store(settings, write=True) as store:
        store.append_fleet_events(events, after, rig_steps)


def _assign(settings: Settings, reason: str, robot: str, t: Target, version: int, name: str) -> FleetEvent:
    return new_fleet_event(
        "assign",
        settings,
        reason,
        robot=robot,
        version=version,
        rollout=name,
        **({"serial": t[1]} if t[0] == "serial" else {"rig": t[1]}),
    )


def _parse_targets(serial_refs: list[str], rig_refs: list[str]) -> dict[Target, int]:
    wanted: dict[Target, int] = {}
    for kind, refs in (("serial", serial_refs), ("rig", rig_refs)):
        for text in refs:
            name, version = records.parse_artifact_ref(text)
            if version is None:
                raise UsageError(f"target '{text}' names no version", f"e.g. {name}@4")
            if (kind, name) in wanted:
                raise UsageError(f"{label((kind, name))} is targeted twice")
            wanted[(kind, name)] = version
    if not wanted:
        raise UsageError("a rollout needs a target", "pass --target SERIAL@N or --rig-target RIG@N")
    return wanted


def start(
    settings: Settings,
    name: str,
    targets: list[str],
    canary: list[str],
    reason: str,
    rig_targets: list[str] | None = None,
) -> Rollout:
    """Start rollout ``name``: ``targets`` SERIAL@N and ``rig_targets`` RIG@N, ``canary`` robots get theirs
    now."""
    check_reason(reason)
    wanted = _parse_targets(targets, rig_targets or [])
    fleet, _ = _read(settings)
    open_ = [r for r in fleet.rollouts.values() if r.closed is None]
    busy = {robot: r.name for r in open_ for robot in r.start.canary}
    for robot in canary:
        if robot in busy:
            raise UsageError(
                f"robot {robot} is already in the canary cohort of open rollout {busy[robot]}",
                f"promote or roll back {busy[robot]} first",
            )
        if robot in fleet.carries and not set(fleet.carries[robot]) & set(wanted):
            carried = ", ".join(label(t) for t in fleet.carries[robot])
            raise UsageError(
                f"canary robot {robot} carries none of the target serials or rigs (it carries {carried})"
            )
    for r in open_:
        for t in sorted(set(r.targets) & set(wanted)):
            raise UsageError(
                f"{ref(t, wanted[t])}: {label(t)} is a target of open rollout {r.name} already "
                f"({ref(t, r.targets[t])}); nothing started",
                f"promote or roll back {r.name} first",
            )
    diffs = target_diffs(settings, fleet, name, wanted)
    head = new_fleet_event(
        "rollout",
        settings,
        reason,
        rollout=name,
        canary=canary,
        targets={n: v for (k, n), v in wanted.items() if k == "serial"},
        rig_targets={n: v for (k, n), v in wanted.items() if k == "rig"},
        diffs={n: d for (k, n), d in diffs.items() if k == "serial"},
        rig_diffs={n: d for (k, n), d in diffs.items() if k == "rig"},
    )
    assigns = [
        _assign(settings, f"canary of rollout {name}", robot, t, wanted[t], name)
        for robot in canary
        for t in fleet.carries.get(robot, [])
        if t in wanted
    ]
    _append(settings, [head, *assigns], fleet.length)
    return _read(settings, name)[0].rollouts[name]


def promote(settings: Settings, name: str, reason: str) -> Rollout:
    """The health gate, then every other robot carrying a target gets its version and each rig target becomes
    its rig's active version (one transaction); the promote event records the gate's inputs."""
    check_reason(reason)
    fleet, rig_active = _read(settings, name)
    rollout = fleet.rollouts[name]
    if rollout.closed is not None:
        raise UsageError(f"rollout {name} is {rollout.closed} already")
    if rollout.failing:
        named = "; ".join(f"{robot}: {', '.join(why)}" for robot, why in sorted(rollout.failing.items()))
        raise VerdictFailed(
            f"rollout {name} is held: canary robot(s) {', '.join(sorted(rollout.failing))} report "
            f"failing checks ({named}); nothing promoted",
            f"roll it back: calibctl fleet rollout rollback {name} --reason ...",
        )
    canary = [r for r in rollout.start.canary if r in rollout.state]
    if rollout.waiting or not canary:
        named = "; ".join(f"{robot}: {', '.join(ts)}" for robot, ts in sorted(rollout.waiting.items()))
        robots = ", ".join(sorted(rollout.waiting)) or "(none)"
        raise UsageError(
            f"rollout {name} cannot be promoted: canary robot(s) {robots} have no health report yet "
            f"({named or 'no canary carries a target'}); nothing promoted",
            "check the canary robots' cameras (`calibctl check`) or ingest their reports "
            "(`calibctl fleet ingest`), then promote again",
        )
    targets = rollout.targets
    assigns = [
        _assign(settings, f"promoted by rollout {name}", robot, t, targets[t], name)
        for robot, state in sorted(rollout.state.items())
        if state == "pending"
        for t in fleet.carries[robot]
        if t in targets
    ]
    steps = [
        RigActivationStep(rig, v, "activate", rig_active.get(rig), f"promoted by rollout {name}: {reason}")
        for (kind, rig), v in sorted(targets.items())
        if kind == "rig" and rig_active.get(rig) != v
    ]
    event = new_fleet_event(
        "promote",
        settings,
        reason,
        rollout=name,
        gate=rollout.evidence,
        restore={s.rig: s.expected_active for s in steps if s.expected_active is not None},
    )
    _append(settings, [*assigns, event], fleet.length, steps)
    return _read(settings, name)[0].rollouts[name]


def rollback(settings: Settings, name: str, reason: str) -> Rollout:
    """Every robot the rollout assigned goes back to the version it ran before and every rig its promote
    activated gets its previous active version back (one transaction); robots that ran nothing before keep the
    record of the rollout's version and are listed as rolled back."""
    check_reason(reason)
    fleet, rig_active = _read(settings, name)
    rollout = fleet.rollouts[name]
    if rollout.closed == "rolled back":
        raise UsageError(f"rollout {name} is rolled back already")
    assigns = []
    for (robot, t), found in sorted(fleet.found.items()):
        previous = found.get(name)  # None: the rollout did not assign it, or it ran nothing before
        if previous is not None and fleet.running[(robot, t)] != previous:
            assigns.append(_assign(settings, f"rolled back by rollout {name}", robot, t, previous, name))
    restore = {} if rollout.promote is None else rollout.promote.restore
    rig_steps = [
        RigActivationStep(
            rig, old, "rollback", rollout.start.rig_targets[rig], f"rolled back by rollout {name}: {reason}"
        )
        for rig, old in sorted(restore.items())
        if rig_active.get(rig) != old
    ]  # put back by hand already: nothing to restore
    closing = new_fleet_event("rollback", settings, reason, rollout=name)
    _append(settings, [*assigns, closing], fleet.length, rig_steps)
    return _read(settings, name)[0].rollouts[name]


def fleet_status(settings: Settings) -> tuple[FleetStatus, list[Rollout]]:
    """``calibctl fleet status``: the robots and every rollout with each robot's state, read in one store
    session."""
    with records.open_store(settings) as store:
        fleet = store.fleet().fleet  # from the newest checkpoint that matches the log
        serial_active, rig_active = store.active_versions()
        robots = robot_states(fleet, serial_active, rig_active)
        _gated(store, fleet)
    return robots, list(fleet.rollouts.values())
