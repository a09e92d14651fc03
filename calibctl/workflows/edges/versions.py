"""The rig's next version with an evidence edge: tree check, lint, carry forward, compare-and-set store.

Every function iterates ``kinds.KINDS`` (package docstring); nothing here names a kind.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from calibctl import __version__
from calibctl.artifacts.calibration import Provenance
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.artifacts.rig import RigCalibration, RigDefinition, RigEdge
from calibctl.config import Settings
from calibctl.core.extrinsics.rig_tree import Edge, orient_tree
from calibctl.errors import NotFoundError, UsageError
from calibctl.workflows.edges.kinds import (
    EVIDENCE_SOURCES,
    KINDS,
    EdgeKind,
    Evidence,
    camera_ref,
    evidence_camera,
    evidence_cameras,
    evidence_of,
    kind_of,
)
from calibctl.workflows.edges.tree import core_edge, edge_key
from calibctl.workflows.exports.frame_names import NAME_RULE, is_ros_name
from calibctl.workflows.store_admin.records import open_store


@dataclass(frozen=True)
class StoredEdge:
    calibration: RigCalibration
    active: bool


def combined_tree_check(rig: RigDefinition, edges: Sequence[RigEdge], parent: str, child: str) -> None:
    """UsageError unless ``parent -> child`` can join ``edges`` as one tree of the rig's frames."""
    known = [*rig.cameras, *rig.frames]
    for frame in (parent, child):
        if frame not in known:
            raise NotFoundError(
                f"frame '{frame}' is not in rig {rig.name} (cameras {', '.join(rig.cameras)}; "
                f"frames {', '.join(rig.frames) or 'none declared'})",
                hint="name a rig member or a frame declared with `calibctl rig add ... --frame NAME`",
            )
    if parent in rig.cameras and child in rig.cameras:
        raise UsageError(
            f"{parent} and {child} are both cameras of rig {rig.name}: the rig solve relates them",
            hint="hand-eye joins a non-camera frame (flange, imu, lidar) to the rig",
        )
    for e in edges:
        if e.source in EVIDENCE_SOURCES and (e.parent, e.child) == (child, parent):
            raise UsageError(
                f"rig {rig.name} already has the edge {child} -> {parent}",
                hint=f"solve it in that direction (--from {child} --to {parent}) to replace it",
            )
    others = [core_edge(e) for e in edges if edge_key(e.parent, e.child) != edge_key(parent, child)]
    try:
        orient_tree([*others, Edge(parent, child, np.eye(4), np.zeros((6, 6)))], rig.root)
    except ValueError as exc:
        raise UsageError(
            f"rig {rig.name}: {parent} -> {child} cannot join the tree: {exc}",
            hint="a frame has one path to every other; attach a frame the tree does not reach",
        ) from None


def checked(
    store: object, rig_name: str, parent: str, child: str, serial: str | None, kind: EdgeKind
) -> tuple[RigDefinition, RigCalibration]:
    """The rig exists and has an active version, the edge can join its tree, and every camera involved
    (a camera frame of the edge, the robot case's --serial) has an active calibration."""
    rig: RigDefinition = store.get_rig(rig_name)  # type: ignore[attr-defined]
    try:
        base: RigCalibration = store.get_rig_calibration(rig_name, None)  # type: ignore[attr-defined]
    except NotFoundError as exc:
        raise NotFoundError(
            f"rig {rig_name} has no active version to add a {kind.source} edge to ({exc.message})",
            hint=f"solve the rig first (`calibctl rig solve {rig_name}`)",
        ) from None
    combined_tree_check(rig, base.edges, parent, child)
    cameras = [f for f in (parent, child) if f in rig.cameras] + ([serial] if serial else [])
    missing = [c for c, v in active_versions(store, cameras).items() if v is None]
    if missing:
        raise NotFoundError(
            f"camera {missing[0]} has no active calibration",
            hint=f"calibrate {missing[0]} (or roll it back to an accepted version), then run {kind.command}",
        )
    return rig, base


def check_target(
    settings: Settings, rig_name: str, parent: str, child: str, serial: str | None, kind: EdgeKind
) -> None:
    """Before any solve (exit 2): the rig, its active version, the tree and the cameras (``checked``)."""
    with open_store(settings) as store:
        checked(store, rig_name, parent, child, serial, kind)


def check_sensor_target(
    settings: Settings, rig_name: str, frame: str, serial: str | None, kind: EdgeKind, option: str
) -> None:
    """Before any solve of a sensor edge ``frame -> serial`` (a LiDAR, an IMU; exit 2, nothing stored):
    ``--serial`` given and a member of the rig, ``frame`` (the ``option`` that named it) a legal ROS name
    declared in the rig and no camera, then ``checked``."""
    if serial is None:
        raise UsageError(
            "--rig needs --serial CAMERA: the rig member whose active calibration the solve uses",
            "the edge pins that calibration (not a camera_info file)",
        )
    if not is_ros_name(frame):
        raise UsageError(f"{option} '{frame}' is not a legal ROS frame name", NAME_RULE)
    with open_store(settings) as store:
        rig = store.get_rig(rig_name)
        if serial not in rig.cameras:
            raise NotFoundError(
                f"camera {serial} is not a member of rig {rig_name} (members {', '.join(rig.cameras)})",
                f"pass --serial with one of them, or `calibctl rig add` a rig with {serial} in it",
            )
        if frame in rig.cameras:
            raise UsageError(
                f"{option} {frame} is a camera of rig {rig_name}",
                f"name the {kind.label} frame, declared with `calibctl rig add ... --frame NAME`",
            )
        checked(store, rig_name, frame, serial, None, kind)


def active_versions(store: object, serials: Sequence[str]) -> dict[str, int | None]:
    out: dict[str, int | None] = {}
    for serial in dict.fromkeys(serials):
        try:
            out[serial] = store.get_artifact(serial, None).version  # type: ignore[attr-defined]
        except NotFoundError:
            out[serial] = None
    return out


def cal_versions(store: object, cal: RigCalibration) -> dict[str, int | None]:
    """The active calibration version now of every camera ``cal``'s evidence was solved with."""
    return active_versions(store, evidence_cameras(evidence_of(cal)))


def _gate_findings(h: Evidence, k: EdgeKind, edge: str) -> list[Finding]:
    return [
        Finding(
            rule=f"{k.rule}-gates",
            severity="error",
            value=g.value,
            threshold=g.threshold,
            message=f"{edge}: gate {g.gate} failed: {g.message}",
            fix=g.hint or f"capture again so every gate passes, then run {k.command} again",
        )
        for g in h.gates
        if not g.passed
    ]


def _sigma_findings(h: Evidence, k: EdgeKind, edge: str) -> list[Finding]:
    if h.status != "accepted":
        return []
    why = k.no_sigma(h)
    if why is not None:
        return [
            Finding(
                rule=f"{k.rule}-uncertainty",
                severity="error",
                message=f"{edge}: no one-sigma ({why})",
                fix="capture more, varied poses: an edge without an uncertainty cannot join a rig tree",
            )
        ]
    sig = k.sigmas(h)
    if sig is None or k.loose_translation_mm is None or k.loose_rotation_deg is None:
        return []
    t, r = sig
    if t <= k.loose_translation_mm and r <= k.loose_rotation_deg:
        return []
    return [
        Finding(
            rule=f"{k.rule}-uncertainty",
            severity="warning",
            value=t,
            threshold=k.loose_translation_mm,
            message=f"{edge}: one-sigma up to {t:.1f} mm, {r:.3f} deg (loose above "
            f"{k.loose_translation_mm:g} mm or {k.loose_rotation_deg:g} deg)",
            fix=k.loose_fix,
        )
    ]


def edge_findings(results: Sequence[Evidence], active: Mapping[str, int | None]) -> list[Finding]:
    """Lint of edge evidence (``handeye-*``, ``lidar-*``): failed gates, a camera re-calibrated since the
    solve, no one-sigma (and, for a kind with loose-sigma thresholds, a loose one: a warning)."""
    out = []
    for h in results:
        k = kind_of(h)
        edge = f"{h.parent_frame} -> {h.child_frame}"
        out += _gate_findings(h, k, edge) + _sigma_findings(h, k, edge)
        cam = evidence_camera(h)
        if cam is not None and cam[0] in active and active[cam[0]] != cam[1]:
            now = active[cam[0]]
            out.append(
                Finding(
                    rule=f"{k.rule}-stale-member",
                    severity="error",
                    message=f"{edge}: solved with {cam[0]}@{cam[1]}, the active one is now "
                    f"{f'{cam[0]}@{now}' if now is not None else 'none'}",
                    fix=f"re-run `{k.rerun}` with the camera's current calibration",
                )
            )
    return out


@dataclass(frozen=True)
class Carried:
    """What a new version keeps of the active one's evidence edges: the edges, the evidence by its
    RigCalibration field (``evidence["handeye"]``, ...: a model_copy update as it is) and the dropped ones
    named."""

    edges: list[RigEdge]
    evidence: dict[str, list[Any]]
    dropped: list[Finding]


def carried_forward(active: RigCalibration | None, versions: Mapping[str, int | None]) -> Carried:
    """The evidence edges a new version keeps from ``active``; a stale one is dropped and named."""
    kept: dict[str, list[Any]] = {k.evidence_field: [] for k in KINDS}
    if active is None:
        return Carried([], kept, [])
    edges: list[RigEdge] = []
    dropped = []
    by_key: dict[tuple[str, str, str], RigEdge] = {
        (e.parent, e.child, e.source): e for e in active.edges if e.source in EVIDENCE_SOURCES
    }
    for h in evidence_of(active):
        k = kind_of(h)
        edge = by_key.get((h.parent_frame, h.child_frame, k.source))
        if edge is None:
            continue
        if edge_findings([h], versions):
            dropped.append(
                Finding(
                    rule=f"{k.rule}-dropped",
                    severity="warning",
                    message=f"{h.parent_frame} -> {h.child_frame} of {active.rig}@{active.version} was "
                    f"solved with {camera_ref(h)}, no longer active: not carried",
                    fix=f"re-run `{k.rerun}` to put the edge back",
                )
            )
            continue
        edges.append(edge)
        kept[k.evidence_field].append(h)
    return Carried(edges, kept, dropped)


def with_evidence(
    base: RigCalibration, result: Evidence, versions: Mapping[str, int | None], settings: Settings
) -> RigCalibration:
    """The next version: ``base`` with the accepted ``result``'s edge added or replacing any evidence edge
    between the same two frames; a rejected result (or one lint rejects) adds none."""
    kind = kind_of(result)
    key = edge_key(result.parent_frame, result.child_frame)
    edge = kind.tree_edge(result) if result.status == "accepted" and kind.no_sigma(result) is None else None
    findings = edge_findings([result], versions)
    accepted = result.status == "accepted" and edge is not None and not has_errors(findings)
    others = base.model_copy(
        update={
            k.evidence_field: [
                h for h in getattr(base, k.evidence_field) if edge_key(h.parent_frame, h.child_frame) != key
            ]
            for k in KINDS
        }
    )
    carried = carried_forward(others, versions)  # the other edges; stale ones dropped and named
    edges = [e for e in base.edges if e.source not in EVIDENCE_SOURCES] + carried.edges
    if accepted and edge is not None:
        edges.append(edge)
    prefixes = tuple(f"{k.rule}-" for k in KINDS)
    lint = [f for f in base.lint if not f.rule.startswith(prefixes)] + carried.dropped + findings
    evidence = dict(carried.evidence)
    evidence[kind.evidence_field] = [*evidence[kind.evidence_field], result]
    prov = Provenance(
        calibctl_version=__version__,
        opencv_version=cv2.__version__,
        station=settings.station,
        operator=settings.operator,
        created_at=utc_now(),
        session_id=base.provenance.session_id,
    )
    return base.model_copy(
        update={
            "version": 1,
            "status": "accepted" if accepted and not has_errors(lint) else "rejected",
            "edges": edges,
            **evidence,
            "lint": lint,
            "provenance": prov,
        }
    )


Build = Callable[[RigCalibration, Mapping[str, int | None]], RigCalibration]


def store_evidence(
    settings: Settings, rig_name: str, result: Evidence, serial: str | None = None, build: Build | None = None
) -> StoredEdge:
    """Store ``build(base, versions)`` (default ``with_evidence``) as the rig's next version,
    compare-and-set on ``base``; active only when accepted. ``serial``: a camera the result used that is
    not a frame of the edge (robot hand-eye)."""
    kind = kind_of(result)
    with open_store(settings, write=True) as store:
        _, base = checked(store, rig_name, result.parent_frame, result.child_frame, serial, kind)
        versions = active_versions(store, evidence_cameras([*evidence_of(base), result]))
        cal = build(base, versions) if build is not None else with_evidence(base, result, versions, settings)
        activate = cal.status == "accepted"
        stored = store.add_rig_calibration(
            cal,
            activate=activate,
            actor=settings.operator,
            station=settings.station,
            reason=f"{kind.source} {result.parent_frame} -> {result.child_frame}",
            based_on=base.version,
        )
    return StoredEdge(stored, activate)
