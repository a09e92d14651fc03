"""A rollout's health gate and what its promote records.

Gate inputs, for every canary robot and every target (serial or rig) it carries, measured at or after the
rollout started (the canary robots run the new version from then on): the stored ``calibctl check`` events of
serial@new version (a check re-tests one physical camera, so it counts for the robot carrying that serial) and
the health reports the robot itself sent about the target (``fleet ingest``) with a verdict: a check (pass),
a gauge ratio (inside the station gauge's 0.99..1.01) and a triage verdict (ok). Time-offset reports carry no
verdict and do not count. One failing input holds the canary; a target without any input yet blocks promote.

The promote event records every input it decided on (id and sha256 of the stored row, so ``db verify`` can
re-check the decision against the stored reports). The rollout event records each target's ``calibctl diff``
against the version its robots ran (verdict and px: recorded, not enforced, since a re-calibration is expected
to differ), computed once at the start from one store session.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from calibctl.artifacts.fleet import GateEvidence, TargetDiff
from calibctl.config import Settings
from calibctl.errors import CalibctlError
from calibctl.store.fleet_ledger import Fleet, Rollout, Target
from calibctl.workflows.camera.distance_gauge import RATIO_LIMITS
from calibctl.workflows.compare.diff import DiffRequest, compare_artifacts
from calibctl.workflows.compare.rig_diff import compare_rig_calibrations
from calibctl.workflows.store_admin import records

if TYPE_CHECKING:
    from calibctl.store.health import GateReport
    from calibctl.store.repository import Store


@dataclass
class Gate:
    """The gate's reading of one open rollout: the inputs, and per canary robot its failing and missing
    targets."""

    evidence: list[GateEvidence] = field(default_factory=list)
    failing: dict[str, list[str]] = field(default_factory=dict)  # robot -> "CAM-1 check report amr-1/x: fail"
    waiting: dict[str, list[str]] = field(default_factory=dict)  # robot -> targets with no input yet

    def state(self, robot: str) -> str:
        return "failed" if self.failing.get(robot) else "canary" if self.waiting.get(robot) else "healthy"


def report_passed(r: GateReport) -> bool:
    """A robot's report read as a gate verdict: check pass, gauge ratio inside the limits, triage ok."""
    if r.kind == "gauge":
        return r.ratio is not None and RATIO_LIMITS[0] <= r.ratio <= RATIO_LIMITS[1]
    return r.verdict == ("pass" if r.kind == "check" else "ok")


def read_gate(store: Store, rollout: Rollout, fleet: Fleet) -> Gate:
    """The gate inputs of ``rollout``'s canary robots from ``store`` (two queries: checks and robots'
    reports)."""
    targets = rollout.targets
    since = rollout.start.at.replace(microsecond=0)  # a report stamped in the start's own second counts
    serials = sorted(name for kind, name in targets if kind == "serial")
    checks = [
        (c, sha)
        for c, sha in store.checks_since(serials, since)
        if c.version == targets[("serial", c.serial)]
    ]
    reports = store.gate_reports(rollout.start.canary, sorted({name for _, name in targets}), since)
    gate = Gate()
    for robot in rollout.start.canary:
        for t in fleet.carries.get(robot, []):
            if t not in targets:
                continue
            kind, name = t
            found = [
                GateEvidence(
                    robot=robot,
                    target=name,
                    source="check",
                    id=c.check_id,
                    sha256=sha,
                    kind="check",
                    passed=c.passed,
                )
                for c, sha in checks
                if kind == "serial" and c.serial == name
            ]
            found += [
                GateEvidence(
                    robot=robot,
                    target=name,
                    rig=kind == "rig",
                    source="report",
                    id=r.source_id,
                    sha256=r.payload_sha256,
                    kind=r.kind,
                    passed=report_passed(r),
                )
                for r in reports
                if r.robot == robot and r.serial == name
            ]
            gate.evidence += found
            if not found:
                gate.waiting.setdefault(robot, []).append(name if kind == "serial" else f"rig {name}")
            for e in found:
                if not e.passed:
                    gate.failing.setdefault(robot, []).append(f"{name} {e.kind} {e.source} {e.id}: fail")
    return gate


def previous_version(fleet: Fleet, name: str, t: Target) -> int | None:
    """The version ``t`` ran on its robots before rollout ``name`` (the most common one), None when none ran
    one."""
    seen: Counter[int] = Counter()
    for (robot, target), running in fleet.running.items():
        if target != t:
            continue
        found = fleet.found[(robot, target)]
        if name not in found:
            seen[running] += 1
        elif (before := found[name]) is not None:
            seen[before] += 1
    return seen.most_common(1)[0][0] if seen else None


def _compare(store: Store, t: Target, old: int, new: int) -> TargetDiff:
    """``calibctl diff`` (or ``diff --rig``) of ``t`` @old against @new; "not compared" with why when it
    cannot."""
    kind, name = t
    a, b = f"{name}@{old}", f"{name}@{new}"
    try:
        if kind == "rig":
            rigs = store.get_rig_calibration(name, old), store.get_rig_calibration(name, new)
            return TargetDiff(previous=old, verdict=compare_rig_calibrations(*rigs, a, b).verdict)
        d = compare_artifacts(store.get_artifact(name, old), store.get_artifact(name, new), DiffRequest(a, b))
    except CalibctlError as exc:
        return TargetDiff(previous=old, verdict="not compared", why=exc.message[:500])
    return TargetDiff(
        previous=old,
        verdict=d.verdict,
        p50_px=d.result.raw.percentiles_px["p50"],
        max_px=d.result.raw.percentiles_px["max"],
    )


def target_diffs(
    settings: Settings, fleet: Fleet, name: str, targets: dict[Target, int]
) -> dict[Target, TargetDiff]:
    """Each of rollout ``name``'s ``targets`` against the version its robots ran before it (none: not
    compared)."""
    out = {}
    with records.open_store(settings) as store:
        for t, version in sorted(targets.items()):
            old = previous_version(fleet, name, t)
            if old is not None and old != version:
                out[t] = _compare(store, t, old, version)
    return out
