"""``calibctl diff --rig A B``: two stored rig versions, pair by pair (core.compare.rig_diff does the
numbers).

Camera pairs get the rotation, translation and baseline change with sigma and the predicted depth-error
change at 1, 2, 5, 10 m; hand-eye and camera-LiDAR edges (a camera to a flange, IMU or LiDAR frame) the
rotation and translation change with sigma. The members' intrinsics are the camera diff's job: when a member's
calibration version differs between the two, a note names the ``calibctl diff`` to run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibctl.artifacts.rig import RigCalibration
from calibctl.config import Settings
from calibctl.core.compare.rig_diff import ALPHA, PairChange, camera_pairs, pair_changes
from calibctl.core.extrinsics.rig_tree import Edge, RigTree, orient_tree
from calibctl.errors import UsageError
from calibctl.workflows.edges.kinds import EVIDENCE_SOURCES
from calibctl.workflows.store_admin import records


@dataclass
class RigDiff:
    a: RigCalibration
    b: RigCalibration
    pairs: list[PairChange]
    edges: list[PairChange]
    notes: list[str] = field(default_factory=list)

    @property
    def ref_a(self) -> str:
        return f"{self.a.rig}@{self.a.version}"

    @property
    def ref_b(self) -> str:
        return f"{self.b.rig}@{self.b.version}"

    @property
    def verdict(self) -> str:
        return "different" if any(p.significant for p in [*self.pairs, *self.edges]) else "same"

    def as_json(self) -> dict[str, Any]:
        def change(p: PairChange) -> dict[str, Any]:
            out = {k: v for k, v in p.__dict__.items() if k != "depth"}
            out["depth"] = [d.__dict__ for d in p.depth]
            return out

        return {
            "a": {"ref": self.ref_a, "status": self.a.status},
            "b": {"ref": self.ref_b, "status": self.b.status},
            "verdict": self.verdict,
            "alpha": ALPHA,
            "pairs": [change(p) for p in self.pairs],
            "edges": [change(p) for p in self.edges],
            "notes": self.notes,
        }


def tree_of(cal: RigCalibration) -> RigTree:
    """The stored edges as core's RigTree. Hand-eye and LiDAR edges are stored as measured (``flange ->
    cam0``, ``lidar -> cam0``), not from the root camera down: oriented as the exports do
    (rig_tree.orient_tree)."""
    return orient_tree(
        [
            Edge(
                e.parent,
                e.child,
                np.array(e.T_parent_child, dtype=np.float64),
                np.array(e.covariance, dtype=np.float64),
            )
            for e in cal.edges
        ],
        cal.root,
    )


def _read(settings: Settings, ref: str) -> RigCalibration:
    name, version = records.parse_artifact_ref(ref)
    with records.open_store(settings) as store:
        return store.get_rig_calibration(name, version)


def diff_rigs(settings: Settings, ref_a: str, ref_b: str) -> RigDiff:
    """Compare two stored rig calibrations (``RIG[@N]`` each)."""
    return compare_rig_calibrations(_read(settings, ref_a), _read(settings, ref_b), ref_a, ref_b)


def compare_rig_calibrations(a: RigCalibration, b: RigCalibration, ref_a: str, ref_b: str) -> RigDiff:
    """``diff_rigs`` of two rig calibrations read already (``ref_a``/``ref_b``: how the user named them)."""
    if a.rig == b.rig and a.version == b.version:
        raise UsageError(
            f"{ref_a} and {ref_b} are both {a.rig}@{a.version}: there is nothing to compare",
            "name two different versions (`calibctl rig history RIG` lists them)",
        )
    tree_a, tree_b = tree_of(a), tree_of(b)
    cameras = [m.serial for m in a.members]
    pairs = camera_pairs(tree_a, tree_b, cameras)
    frames_b = {(e.parent, e.child) for e in b.edges}
    edges = [
        (e.parent, e.child)
        for e in a.edges
        if e.source in EVIDENCE_SOURCES and (e.parent, e.child) in frames_b
    ]
    if not pairs and not edges:
        raise UsageError(
            f"{ref_a} and {ref_b} share no camera pair and no evidence edge (hand-eye, LiDAR, IMU)",
            "compare two versions of one rig, or rigs with two cameras in common",
        )
    changes = pair_changes(tree_a, tree_b, [*pairs, *edges], no_depth=edges)
    notes = [
        f"{ref} is a REJECTED rig calibration (compared as asked; a robot must not load it)"
        for ref, cal in ((f"{a.rig}@{a.version}", a), (f"{b.rig}@{b.version}", b))
        if cal.status == "rejected"
    ]
    members_b = {m.serial: m for m in b.members}
    for m in a.members:
        other = members_b.get(m.serial)
        if other is not None and (other.version != m.version or other.refined or m.refined):
            notes.append(
                f"{m.serial}'s intrinsics differ between the two (@{m.version}{' refined' * m.refined} and "
                f"@{other.version}{' refined' * other.refined}): `calibctl diff {m.serial}@{m.version} "
                f"{m.serial}@{other.version}` compares them"
            )
    return RigDiff(a, b, changes[: len(pairs)], changes[len(pairs) :], notes)
