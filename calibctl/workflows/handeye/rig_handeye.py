"""Hand-eye edges in the rig tree: a gated hand-eye result becomes the rig's next version.

The choice (docs/conventions.md "Rig trees", docs/handeye.md): a rig version is the whole tree a
robot loads, so ``calibctl handeye ... --rig RIG`` stores the rig's next immutable version = the
active version's edges with this edge (``source: "hand-eye"``) added or replaced, and the sealed
hand-eye result as its evidence (``RigCalibration.handeye``). History, show, rollback and export are
then the rig's own, and a rollback moves camera and hand-eye edges together. A rejected result is
stored as a rejected version (never active) that carries *no* edge for that frame pair, so no
transform of it looks accepted. A rig re-solve carries the active version's hand-eye edges forward,
except one whose camera was re-calibrated since (it would be stale; named in the findings).

Concurrency: the new version (and a rig re-solve's, which carries the active hand-eye edges) is
written compare-and-set on the base version it was built from. When
another writer moved the rig's active version in between (another hand-eye edge, a re-solve, a
rollback), nothing is stored and the command exits 2 naming the newer version; it is never rebased
silently: the tree check, the stale-camera lint and the carried edges were judged against the base,
and the other change may be a rollback that the operator meant to keep out of the tree. Re-running
the command builds on the new active version.

Frames: a hand-eye edge joins a rig member camera or a frame declared with ``rig add --frame`` to
another frame of the rig; the combined edges must stay a tree (core.extrinsics.rig_tree.orient_tree).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calibctl import __version__
from calibctl.artifacts.calibration import Provenance
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.handeye import HandEyeResult
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.artifacts.rig import RigCalibration, RigDefinition, RigEdge
from calibctl.config import Settings
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.rig_tree import Edge, T_to_pose, orient_tree, propagate
from calibctl.errors import NotFoundError, UsageError
from calibctl.workflows.store_admin.records import open_store

HANDEYE_RULES = ("handeye-gates", "handeye-stale-member", "handeye-uncertainty", "handeye-dropped")


@dataclass(frozen=True)
class StoredEdge:
    calibration: RigCalibration
    active: bool


def _key(parent: str, child: str) -> frozenset[str]:
    return frozenset((parent, child))


def _core_edge(e: RigEdge) -> Edge:
    return Edge(e.parent, e.child, np.array(e.T_parent_child), np.array(e.covariance))


def combined_tree_check(rig: RigDefinition, edges: Sequence[RigEdge], parent: str, child: str) -> None:
    """UsageError unless ``parent -> child`` can join ``edges`` as one tree of the rig's frames."""
    known = [*rig.cameras, *rig.frames]
    for frame in (parent, child):
        if frame not in known:
            raise NotFoundError(f"frame '{frame}' is not in rig {rig.name} (cameras {', '.join(rig.cameras)}; "
                                f"frames {', '.join(rig.frames) or 'none declared'})",
                                hint="name a rig member or a frame declared with `calibctl rig add ... --frame NAME`")
    if parent in rig.cameras and child in rig.cameras:
        raise UsageError(f"{parent} and {child} are both cameras of rig {rig.name}: the rig solve relates them",
                         hint="hand-eye joins a non-camera frame (flange, imu, lidar) to the rig")
    for e in edges:
        if e.source == "hand-eye" and (e.parent, e.child) == (child, parent):
            raise UsageError(f"rig {rig.name} already has the edge {child} -> {parent}",
                             hint=f"solve it in that direction (--from {child} --to {parent}) to replace it")
    others = [_core_edge(e) for e in edges if _key(e.parent, e.child) != _key(parent, child)]
    try:
        orient_tree([*others, Edge(parent, child, np.eye(4), np.zeros((6, 6)))], rig.root)
    except ValueError as exc:
        raise UsageError(f"rig {rig.name}: {parent} -> {child} cannot join the tree: {exc}",
                         hint="a frame has one path to every other; attach a frame the tree does not reach") from None


def check_target(settings: Settings, rig_name: str, parent: str, child: str, serial: str | None = None) -> None:
    """Before any solve (exit 2): see ``_checked``."""
    with open_store(settings) as store:
        _checked(store, rig_name, parent, child, serial)


def _checked(store: object, rig_name: str, parent: str, child: str,
             serial: str | None) -> tuple[RigDefinition, RigCalibration]:
    """The rig exists and has an active version, the edge can join its tree, and every camera involved
    (a camera frame of the edge, the robot case's --serial) has an active calibration."""
    rig: RigDefinition = store.get_rig(rig_name)  # type: ignore[attr-defined]
    base = _active(store, rig_name)
    combined_tree_check(rig, base.edges, parent, child)
    cameras = [f for f in (parent, child) if f in rig.cameras] + ([serial] if serial else [])
    missing = [c for c, v in active_versions(store, cameras).items() if v is None]
    if missing:
        raise NotFoundError(f"camera {missing[0]} has no active calibration",
                            hint=f"calibrate {missing[0]} (or roll it back to an accepted version), then run handeye")
    return rig, base


def _active(store: object, rig_name: str) -> RigCalibration:
    try:
        cal: RigCalibration = store.get_rig_calibration(rig_name, None)  # type: ignore[attr-defined]
    except NotFoundError as exc:
        raise NotFoundError(f"rig {rig_name} has no active version to add a hand-eye edge to ({exc.message})",
                            hint=f"solve the rig first (`calibctl rig solve {rig_name}`)") from None
    return cal


def rig_edge(result: HandEyeResult) -> RigEdge:
    """An accepted result as a tree edge; its covariance re-expressed over (rvec, tvec) of T_parent_child."""
    assert result.transform is not None and result.uncertainty is not None
    R = se3.rotation_from_quaternion(np.array(result.transform.rotation_wxyz))
    T = se3.transform(R, list(result.transform.translation_m))

    def pose(d: np.ndarray) -> np.ndarray:  # the result's perturbation: R = exp(d_rot) R0, t = t0 + d_t
        return T_to_pose(se3.transform(se3.rotation_from_rotvec(d[:3]) @ R, T[:3, 3] + d[3:]))

    cov = propagate(pose, np.zeros(6), np.array(result.uncertainty.covariance))
    e = Edge(result.parent_frame, result.child_frame, T, cov)
    return RigEdge(parent=e.parent, child=e.child, T_parent_child=tuple(map(tuple, T.tolist())),
                   covariance=cov.tolist(), translation_mm=e.translation_mm, sigma_translation_mm=e.sigma_translation_mm,
                   rotation_deg=e.rotation_deg, sigma_rotation_deg=e.sigma_rotation_deg, source="hand-eye")


def _camera(result: HandEyeResult) -> tuple[str, int] | None:
    ref = result.provenance.camera
    if not ref or "@" not in ref:
        return None
    serial, _, version = ref.rpartition("@")
    return (serial, int(version)) if version.isdigit() else None


def handeye_findings(results: Sequence[HandEyeResult], active_versions: Mapping[str, int | None]) -> list[Finding]:
    """Lint of hand-eye evidence: failed gates, a camera re-calibrated since the solve, no one-sigma."""
    out = []
    for h in results:
        edge = f"{h.parent_frame} -> {h.child_frame}"
        for g in h.gates:
            if not g.passed:
                out.append(Finding(rule="handeye-gates", severity="error", value=g.value, threshold=g.threshold,
                                   message=f"{edge}: gate {g.gate} failed: {g.message}",
                                   fix=g.hint or "re-record the motions so every gate passes, then run handeye again"))
        if h.status == "accepted" and h.uncertainty is None:
            out.append(Finding(rule="handeye-uncertainty", severity="error",
                               message=f"{edge}: no one-sigma ({h.uncertainty_refused_reason or 'not estimable'})",
                               fix="record more motions: an edge without an uncertainty cannot join a rig tree"))
        cam = _camera(h)
        if cam is not None and cam[0] in active_versions and active_versions[cam[0]] != cam[1]:
            now = active_versions[cam[0]]
            out.append(Finding(
                rule="handeye-stale-member", severity="error",
                message=f"{edge}: solved with {cam[0]}@{cam[1]}, the active one is now "
                        f"{f'{cam[0]}@{now}' if now is not None else 'none'}",
                fix="re-run `calibctl handeye ... --rig` with the camera's current calibration"))
    return out


def active_versions(store: object, serials: Sequence[str]) -> dict[str, int | None]:
    out: dict[str, int | None] = {}
    for serial in dict.fromkeys(serials):
        try:
            out[serial] = store.get_artifact(serial, None).version  # type: ignore[attr-defined]
        except NotFoundError:
            out[serial] = None
    return out


def handeye_cameras(results: Sequence[HandEyeResult]) -> list[str]:
    return [c[0] for c in map(_camera, results) if c is not None]


def carried_forward(active: RigCalibration | None,
                    versions: Mapping[str, int | None]) -> tuple[list[RigEdge], list[HandEyeResult], list[Finding]]:
    """The hand-eye edges a rig re-solve keeps from the active version; a stale one is dropped and named."""
    if active is None:
        return [], [], []
    edges, results, findings = [], [], []
    by_key = {(e.parent, e.child): e for e in active.edges if e.source == "hand-eye"}
    for h in active.handeye:
        edge = by_key.get((h.parent_frame, h.child_frame))
        if edge is None:
            continue
        if handeye_findings([h], versions):
            findings.append(Finding(rule="handeye-dropped", severity="warning",
                                    message=f"{h.parent_frame} -> {h.child_frame} of {active.rig}@{active.version} "
                                            f"was solved with {h.provenance.camera}, no longer active: not carried",
                                    fix="re-run `calibctl handeye ... --rig` to put the edge back"))
            continue
        edges.append(edge)
        results.append(h)
    return edges, results, findings


def with_handeye(base: RigCalibration, result: HandEyeResult,
                 versions: Mapping[str, int | None], settings: Settings) -> RigCalibration:
    """The next version: ``base`` with the edge of ``result`` added or replaced (rejected: removed)."""
    key = _key(result.parent_frame, result.child_frame)
    findings = handeye_findings([result], versions)
    accepted = result.status == "accepted" and not has_errors(findings)
    others = base.model_copy(update={"handeye": [h for h in base.handeye if _key(h.parent_frame, h.child_frame) != key]})
    kept, evidence, dropped = carried_forward(others, versions)  # the other edges; stale ones dropped and named
    edges = [e for e in base.edges if e.source != "hand-eye"] + kept
    if accepted:
        edges.append(rig_edge(result))
    lint = [f for f in base.lint if not f.rule.startswith("handeye-")] + dropped + findings
    prov = Provenance(calibctl_version=__version__, opencv_version=cv2.__version__, station=settings.station,
                      operator=settings.operator, created_at=utc_now(), session_id=base.provenance.session_id)
    return base.model_copy(update={
        "version": 1, "status": "accepted" if accepted and not has_errors(lint) else "rejected", "edges": edges,
        "handeye": [*evidence, result], "lint": lint, "provenance": prov})


def store_handeye(settings: Settings, rig_name: str, result: HandEyeResult) -> StoredEdge:
    """Store ``result`` as the rig's next version; active only when accepted."""
    camera = _camera(result)
    with open_store(settings, write=True) as store:
        _, base = _checked(store, rig_name, result.parent_frame, result.child_frame, camera[0] if camera else None)
        versions = active_versions(store, handeye_cameras([*base.handeye, result]))
        cal = with_handeye(base, result, versions, settings)
        activate = cal.status == "accepted"
        stored = store.add_rig_calibration(cal, activate=activate, actor=settings.operator, station=settings.station,
                                           reason=f"hand-eye {result.parent_frame} -> {result.child_frame}",
                                           based_on=base.version)
    return StoredEdge(stored, activate)


def edge_export(cal: RigCalibration, edge: str, fmt: str, frames: Mapping[str, str] | None = None) -> str:
    """One hand-eye edge of a stored version, ``FROM:TO``: its result document (json) or /tf_static (tf, its
    frames renamed by ``frames``: the rig export's robot frame names)."""
    from calibctl.workflows.handeye.handeye import tf_static_yaml

    parent, sep, child = edge.partition(":")
    if not sep or not parent or not child:
        raise UsageError(f"--edge must be FROM:TO, got {edge!r}")
    found = next((h for h in cal.handeye if (h.parent_frame, h.child_frame) == (parent, child)), None)
    if found is None:
        have = ", ".join(f"{h.parent_frame}:{h.child_frame}" for h in cal.handeye) or "none"
        raise NotFoundError(f"rig {cal.rig}@{cal.version} has no hand-eye edge {parent} -> {child} (it has: {have})",
                            hint=f"see `calibctl rig show {cal.rig}@{cal.version}`")
    if fmt == "json":
        return found.model_dump_json(indent=2) + "\n"
    if fmt == "tf":
        return tf_static_yaml(found, frames)
    raise UsageError(f"--edge exports json or tf, not {fmt}")
