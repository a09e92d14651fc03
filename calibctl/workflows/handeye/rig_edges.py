"""Evidence-backed edges of a rig tree: what ``handeye --rig`` and ``lidar solve --rig`` share.

A hand-eye edge (``source: "hand-eye"``, evidence a HandEyeResult in ``RigCalibration.handeye``) and a
camera-LiDAR edge (``source: "lidar-board"``, evidence a LidarEdgeResult in ``RigCalibration.lidar``)
join the rig's tree the same way (rig_handeye module docstring): the rig's next immutable version is
the active one with this edge added or replaced, its evidence sealed inside it, written
compare-and-set on that base; a rejected result is stored as a rejected version carrying its evidence
and no edge; the other evidence edges are carried forward unless their camera was re-calibrated since
(dropped and named). Lint speaks per kind: ``handeye-*`` and ``lidar-*`` rules.

This module lives in the handeye room (below ``lidar`` and ``rig``) and knows both evidence kinds
through their artifacts only, so the rig re-solve, rig lint and a hand-eye write carry LiDAR edges too.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calibctl import __version__
from calibctl.artifacts.calibration import Provenance
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.handeye import HandEyeResult
from calibctl.artifacts.lidar import LidarEdgeResult
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.artifacts.rig import RigCalibration, RigDefinition, RigEdge
from calibctl.config import Settings
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.rig_tree import Edge, T_to_pose, orient_tree, propagate
from calibctl.errors import NotFoundError, UsageError
from calibctl.workflows.store_admin.records import open_store

Evidence = HandEyeResult | LidarEdgeResult
# loose-edge warnings of a LiDAR edge: sigmas a station set of 10+ varied poses stays well under
LIDAR_LOOSE_TRANSLATION_MM = 10.0
LIDAR_LOOSE_ROTATION_DEG = 0.5


@dataclass(frozen=True)
class EdgeKind:
    source: str  # RigEdge.source
    rule: str  # lint rule prefix
    rerun: str  # the command that puts the edge back
    command: str  # what the user runs, for "solve the rig first, then ..."


HANDEYE = EdgeKind("hand-eye", "handeye", "calibctl handeye ... --rig", "handeye")
LIDAR = EdgeKind("lidar-board", "lidar", "calibctl lidar solve ... --rig", "lidar solve")
EVIDENCE_SOURCES = (HANDEYE.source, LIDAR.source)


@dataclass(frozen=True)
class StoredEdge:
    calibration: RigCalibration
    active: bool


def kind_of(ev: Evidence) -> EdgeKind:
    return LIDAR if isinstance(ev, LidarEdgeResult) else HANDEYE


def evidence_of(cal: RigCalibration) -> list[Evidence]:
    return [*cal.handeye, *cal.lidar]


def _key(parent: str, child: str) -> frozenset[str]:
    return frozenset((parent, child))


def _core_edge(e: RigEdge) -> Edge:
    return Edge(e.parent, e.child, np.array(e.T_parent_child), np.array(e.covariance))


def tree_edge(
    parent: str, child: str, T_parent_child: np.ndarray, covariance_left: np.ndarray, source: str
) -> RigEdge:
    """A solved T_parent_child as a tree edge. ``covariance_left`` is over the solvers' perturbation (R =
    exp(d_rot) R0, t = t0 + d_t; hand-eye and LiDAR alike), re-expressed over (rvec, tvec) as the tree keeps it."""
    T = np.asarray(T_parent_child, np.float64)

    def pose(d: np.ndarray) -> np.ndarray:
        return T_to_pose(se3.transform(se3.rotation_from_rotvec(d[:3]) @ T[:3, :3], T[:3, 3] + d[3:]))

    cov = propagate(pose, np.zeros(6), covariance_left)
    e = Edge(parent, child, T, cov)
    return RigEdge(
        parent=parent,
        child=child,
        T_parent_child=tuple(map(tuple, T.tolist())),
        covariance=cov.tolist(),
        translation_mm=e.translation_mm,
        sigma_translation_mm=e.sigma_translation_mm,
        rotation_deg=e.rotation_deg,
        sigma_rotation_deg=e.sigma_rotation_deg,
        source=source,
    )


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
    others = [_core_edge(e) for e in edges if _key(e.parent, e.child) != _key(parent, child)]
    try:
        orient_tree([*others, Edge(parent, child, np.eye(4), np.zeros((6, 6)))], rig.root)
    except ValueError as exc:
        raise UsageError(
            f"rig {rig.name}: {parent} -> {child} cannot join the tree: {exc}",
            hint="a frame has one path to every other; attach a frame the tree does not reach",
        ) from None


def checked(
    store: object, rig_name: str, parent: str, child: str, serial: str | None, kind: EdgeKind = HANDEYE
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


def active_versions(store: object, serials: Sequence[str]) -> dict[str, int | None]:
    out: dict[str, int | None] = {}
    for serial in dict.fromkeys(serials):
        try:
            out[serial] = store.get_artifact(serial, None).version  # type: ignore[attr-defined]
        except NotFoundError:
            out[serial] = None
    return out


def camera_ref(ev: Evidence) -> str | None:
    """SERIAL@VERSION of the camera calibration the evidence was solved with, when it names one."""
    return ev.camera if isinstance(ev, LidarEdgeResult) else ev.provenance.camera


def evidence_camera(ev: Evidence) -> tuple[str, int] | None:
    """(serial, version) of ``camera_ref``."""
    ref = camera_ref(ev)
    if not ref or "@" not in ref:
        return None
    serial, _, version = ref.rpartition("@")
    return (serial, int(version)) if version.isdigit() else None


def evidence_cameras(results: Sequence[Evidence]) -> list[str]:
    return [c[0] for c in map(evidence_camera, results) if c is not None]


def cal_versions(store: object, cal: RigCalibration) -> dict[str, int | None]:
    """The active calibration version now of every camera ``cal``'s evidence was solved with."""
    return active_versions(store, evidence_cameras(evidence_of(cal)))


def _no_sigma(ev: Evidence) -> str | None:
    """Why an accepted result has no usable one-sigma, or None."""
    if isinstance(ev, HandEyeResult):
        return None if ev.uncertainty is not None else (ev.uncertainty_refused_reason or "not estimable")
    if ev.transform is None:
        return "no transform"
    if not np.all(np.linalg.eigvalsh(np.array(ev.transform.covariance)) > 0):
        return "the 6x6 covariance is not positive definite"
    return None


def edge_findings(results: Sequence[Evidence], active: Mapping[str, int | None]) -> list[Finding]:
    """Lint of edge evidence (``handeye-*``, ``lidar-*``): failed gates, a camera re-calibrated since the
    solve, no one-sigma (and for a LiDAR edge, a loose one: a warning)."""
    out = []
    for h in results:
        k = kind_of(h)
        edge = f"{h.parent_frame} -> {h.child_frame}"
        for g in h.gates:
            if not g.passed:
                out.append(
                    Finding(
                        rule=f"{k.rule}-gates",
                        severity="error",
                        value=g.value,
                        threshold=g.threshold,
                        message=f"{edge}: gate {g.gate} failed: {g.message}",
                        fix=g.hint or f"capture again so every gate passes, then run {k.command} again",
                    )
                )
        why = _no_sigma(h) if h.status == "accepted" else None
        if why is not None:
            out.append(
                Finding(
                    rule=f"{k.rule}-uncertainty",
                    severity="error",
                    message=f"{edge}: no one-sigma ({why})",
                    fix="capture more, varied poses: an edge without an uncertainty cannot join a rig tree",
                )
            )
        elif isinstance(h, LidarEdgeResult) and h.status == "accepted" and h.transform is not None:
            t, r = max(h.transform.sigma_translation_mm), max(h.transform.sigma_rotation_deg)
            if t > LIDAR_LOOSE_TRANSLATION_MM or r > LIDAR_LOOSE_ROTATION_DEG:
                out.append(
                    Finding(
                        rule="lidar-uncertainty",
                        severity="warning",
                        value=t,
                        threshold=LIDAR_LOOSE_TRANSLATION_MM,
                        message=f"{edge}: one-sigma up to {t:.1f} mm, {r:.3f} deg (loose above "
                        f"{LIDAR_LOOSE_TRANSLATION_MM:g} mm or {LIDAR_LOOSE_ROTATION_DEG:g} deg)",
                        fix="add poses nearer the LiDAR and tilted further",
                    )
                )
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
    """What a new version keeps of the active one's evidence edges."""

    edges: list[RigEdge]
    handeye: list[HandEyeResult]
    lidar: list[LidarEdgeResult]
    dropped: list[Finding]


def carried_forward(active: RigCalibration | None, versions: Mapping[str, int | None]) -> Carried:
    """The evidence edges a new version keeps from ``active``; a stale one is dropped and named."""
    if active is None:
        return Carried([], [], [], [])
    edges: list[RigEdge] = []
    kept: list[Evidence] = []
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
        kept.append(h)
    return Carried(
        edges,
        [h for h in kept if isinstance(h, HandEyeResult)],
        [h for h in kept if isinstance(h, LidarEdgeResult)],
        dropped,
    )


def with_evidence(
    base: RigCalibration,
    result: Evidence,
    edge: RigEdge | None,
    versions: Mapping[str, int | None],
    settings: Settings,
) -> RigCalibration:
    """The next version: ``base`` with ``edge`` (the accepted ``result``'s) added or replacing any evidence
    edge between the same two frames; a rejected result (or one lint rejects) adds none."""
    key = _key(result.parent_frame, result.child_frame)
    findings = edge_findings([result], versions)
    accepted = result.status == "accepted" and edge is not None and not has_errors(findings)
    others = base.model_copy(
        update={
            "handeye": [h for h in base.handeye if _key(h.parent_frame, h.child_frame) != key],
            "lidar": [h for h in base.lidar if _key(h.parent_frame, h.child_frame) != key],
        }
    )
    carried = carried_forward(others, versions)  # the other edges; stale ones dropped and named
    edges = [e for e in base.edges if e.source not in EVIDENCE_SOURCES] + carried.edges
    if accepted and edge is not None:
        edges.append(edge)
    prefixes = tuple(f"{k.rule}-" for k in (HANDEYE, LIDAR))
    lint = [f for f in base.lint if not f.rule.startswith(prefixes)] + carried.dropped + findings
    handeye, lidar = carried.handeye, carried.lidar
    if isinstance(result, LidarEdgeResult):
        lidar = [*lidar, result]
    else:
        handeye = [*handeye, result]
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
            "handeye": handeye,
            "lidar": lidar,
            "lint": lint,
            "provenance": prov,
        }
    )


def store_evidence(
    settings: Settings,
    rig_name: str,
    result: Evidence,
    build: Callable[[RigCalibration, Mapping[str, int | None]], RigCalibration],
    serial: str | None = None,
) -> StoredEdge:
    """Store ``build(base, versions)`` as the rig's next version, compare-and-set on ``base``; active only
    when accepted. ``serial``: a camera the result used that is not a frame of the edge (robot hand-eye)."""
    with open_store(settings, write=True) as store:
        _, base = checked(store, rig_name, result.parent_frame, result.child_frame, serial, kind_of(result))
        versions = active_versions(store, evidence_cameras([*evidence_of(base), result]))
        cal = build(base, versions)
        activate = cal.status == "accepted"
        stored = store.add_rig_calibration(
            cal,
            activate=activate,
            actor=settings.operator,
            station=settings.station,
            reason=f"{kind_of(result).source} {result.parent_frame} -> {result.child_frame}",
            based_on=base.version,
        )
    return StoredEdge(stored, activate)
