"""A solved T_parent_child with its covariance as an edge of the rig tree (core.extrinsics.rig_tree)."""

from __future__ import annotations

import numpy as np

from calibctl.artifacts.rig import RigEdge
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.rig_tree import Edge, T_to_pose, propagate


def tree_edge(
    parent: str, child: str, T_parent_child: np.ndarray, covariance_left: np.ndarray, source: str
) -> RigEdge:
    """A solved T_parent_child as a tree edge. ``covariance_left`` is over the solvers' perturbation (R =
    exp(d_rot) R0, t = t0 + d_t; every kind alike), re-expressed over (rvec, tvec) as the tree keeps it."""
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


def core_edge(e: RigEdge) -> Edge:
    return Edge(e.parent, e.child, np.array(e.T_parent_child), np.array(e.covariance))


def edge_key(parent: str, child: str) -> frozenset[str]:
    """The two frames of an edge, either direction."""
    return frozenset((parent, child))
