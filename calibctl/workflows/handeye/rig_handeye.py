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

The machinery (next version, carry forward, lint rules, compare-and-set) is shared with the camera-LiDAR
edges of ``calibctl lidar solve --rig`` in ``rig_edges``; this module adds the hand-eye specifics.

Frames: a hand-eye edge joins a rig member camera or a frame declared with ``rig add --frame`` to
another frame of the rig; the combined edges must stay a tree (core.extrinsics.rig_tree.orient_tree).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from calibctl.artifacts.handeye import HandEyeResult
from calibctl.artifacts.rig import RigCalibration, RigEdge
from calibctl.config import Settings
from calibctl.core.extrinsics import se3
from calibctl.errors import NotFoundError, UsageError
from calibctl.workflows.handeye import rig_edges
from calibctl.workflows.handeye.rig_edges import StoredEdge, active_versions
from calibctl.workflows.store_admin.records import open_store

HANDEYE_RULES = ("handeye-gates", "handeye-stale-member", "handeye-uncertainty", "handeye-dropped")
__all__ = [
    "HANDEYE_RULES",
    "StoredEdge",
    "active_versions",
    "check_target",
    "edge_export",
    "rig_edge",
    "store_handeye",
    "with_handeye",
]


def check_target(
    settings: Settings, rig_name: str, parent: str, child: str, serial: str | None = None
) -> None:
    """Before any solve (exit 2): the rig, its active version, the tree and the cameras (rig_edges.checked)."""
    with open_store(settings) as store:
        rig_edges.checked(store, rig_name, parent, child, serial)


def rig_edge(result: HandEyeResult) -> RigEdge:
    """An accepted result as a tree edge; its covariance re-expressed over (rvec, tvec) of T_parent_child."""
    assert result.transform is not None and result.uncertainty is not None
    R = se3.rotation_from_quaternion(np.array(result.transform.rotation_wxyz))
    T = se3.transform(R, list(result.transform.translation_m))
    return rig_edges.tree_edge(
        result.parent_frame,
        result.child_frame,
        T,
        np.array(result.uncertainty.covariance),
        rig_edges.HANDEYE.source,
    )


def with_handeye(
    base: RigCalibration, result: HandEyeResult, versions: Mapping[str, int | None], settings: Settings
) -> RigCalibration:
    """The next version: ``base`` with the edge of ``result`` added or replaced (rejected: removed)."""
    edge = rig_edge(result) if result.status == "accepted" and result.uncertainty is not None else None
    return rig_edges.with_evidence(base, result, edge, versions, settings)


def store_handeye(settings: Settings, rig_name: str, result: HandEyeResult) -> StoredEdge:
    """Store ``result`` as the rig's next version; active only when accepted."""
    camera = rig_edges.evidence_camera(result)
    return rig_edges.store_evidence(
        settings,
        rig_name,
        result,
        lambda base, versions: with_handeye(base, result, versions, settings),
        camera[0] if camera else None,
    )


def edge_export(cal: RigCalibration, edge: str, fmt: str, frames: Mapping[str, str] | None = None) -> str:
    """One hand-eye or LiDAR edge of a stored version, ``FROM:TO``: its result document (json) or /tf_static
    (tf, its frames renamed by ``frames``: the rig export's robot frame names)."""
    from calibctl.workflows.exports.rig_exports import tf_message
    from calibctl.workflows.handeye.handeye import tf_static_yaml

    parent, sep, child = edge.partition(":")
    if not sep or not parent or not child:
        raise UsageError(f"--edge must be FROM:TO, got {edge!r}")
    evidence = rig_edges.evidence_of(cal)
    found = next((h for h in evidence if (h.parent_frame, h.child_frame) == (parent, child)), None)
    if found is None:
        have = ", ".join(f"{h.parent_frame}:{h.child_frame}" for h in evidence) or "none"
        raise NotFoundError(
            f"rig {cal.rig}@{cal.version} has no hand-eye or LiDAR edge {parent} -> {child} (it has: {have})",
            hint=f"see `calibctl rig show {cal.rig}@{cal.version}`",
        )
    if fmt == "json":
        return found.model_dump_json(indent=2) + "\n"
    if fmt != "tf":
        raise UsageError(f"--edge exports json or tf, not {fmt}")
    if isinstance(found, HandEyeResult):
        return tf_static_yaml(found, frames)
    if found.transform is None or found.status != "accepted":
        raise UsageError(
            f"the LiDAR result {parent} -> {child} of {cal.rig}@{cal.version} was rejected: no transform "
            "is published"
        )
    w, x, y, z = found.transform.quaternion_wxyz
    name = (frames or {}).get
    t = [row[3] for row in found.transform.T_lidar_cam[:3]]
    return (
        f"# calibctl lidar {parent} -> {child} of rig {cal.rig}@{cal.version} sha256 {cal.content_sha256}\n"
        + tf_message([(name(parent) or parent, name(child) or child, t, (x, y, z, w))])
    )
