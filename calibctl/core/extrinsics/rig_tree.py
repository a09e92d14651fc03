"""A rig's extrinsics as a tree of named frames with one root, and the numbers read off it.

Conventions (docs/conventions.md): ``T_a_b`` (4, 4) float64 maps points in frame ``b`` into frame
``a``, metres; chains read ``T_a_c = T_a_b @ T_b_c``. A 6-vector pose is (rvec rad, tvec m) of OpenCV.

Why a tree and not a set of pairs: n cameras have n(n-1)/2 pairwise transforms but only n - 1
independent ones; pairs stored separately disagree around loops. A tree has one path between any
two frames, so every pairwise transform is derived and consistent. An edge is any parent -> child
frame with its 6x6 covariance, so a non-camera edge (a hand-eye ``flange -> cam0``) can hang off
the same tree later without changing its shape.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.se3 import invert, rotation_angle_deg

# Step of the central differences that carry a covariance through a transform chain: rotations
# (rad) and translations (m) are both far from 1e-7 in any real rig, and the functions are smooth.
PROPAGATION_STEP = 1e-7


def pose_to_T(pose: np.ndarray) -> np.ndarray:
    """(6,) rvec (rad), tvec (m) -> (4, 4) float64 T."""
    p = np.asarray(pose, dtype=np.float64).reshape(6)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(p[:3].reshape(3, 1))[0]
    T[:3, 3] = p[3:]
    return T


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (3,) Rodrigues vector (rad), smooth down to zero angle.

    Why not cv2.Rodrigues alone: it returns exactly 0 below ~1e-5 rad, which zeroes the derivative a
    loop-closure residual (a near-identity rotation) needs for its covariance.
    """
    return se3.rotvecs_from_rotations(np.asarray(R, dtype=np.float64)[:3, :3])[0]


def T_to_pose(T: np.ndarray) -> np.ndarray:
    """(4, 4) T -> (6,) float64 rvec (rad), tvec (m)."""
    T = np.asarray(T, dtype=np.float64)
    return np.concatenate([rotation_vector(T[:3, :3]), T[:3, 3]])


def propagate(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """First-order covariance of fn(x) for x ~ N(x, cov): J cov J^T, J by central differences."""
    x = np.asarray(x, dtype=np.float64)
    f0 = np.atleast_1d(fn(x))
    J = np.zeros((f0.size, x.size))
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = PROPAGATION_STEP
        J[:, i] = (np.atleast_1d(fn(x + dx)) - np.atleast_1d(fn(x - dx))) / (2 * PROPAGATION_STEP)
    out = J @ cov @ J.T
    return np.asarray(0.5 * (out + out.T))


def sigma_translation_mm(cov6: np.ndarray, t_m: np.ndarray) -> float:
    """One-sigma of |t| (mm) from a (6, 6) pose covariance (rvec rad, tvec m)."""
    t = np.asarray(t_m, dtype=np.float64).reshape(3)
    g = t / max(float(np.linalg.norm(t)), 1e-12)
    return float(np.sqrt(max(g @ cov6[3:, 3:] @ g, 0.0)) * 1e3)


def sigma_rotation_deg(cov6: np.ndarray) -> float:
    """One-sigma of the rotation along its least certain axis, degrees (sqrt of the largest eigenvalue)."""
    return float(np.rad2deg(np.sqrt(max(float(np.linalg.eigvalsh(cov6[:3, :3])[-1]), 0.0))))


@dataclass(frozen=True)
class Edge:
    """One parent -> child transform of the tree.

    Attributes:
        parent, child: frame names (a camera's frame is its serial).
        T_parent_child: (4, 4) float64, metres.
        covariance: (6, 6) float64 of the pose vector (rvec rad, tvec m) of T_parent_child.
    """

    parent: str
    child: str
    T_parent_child: np.ndarray
    covariance: np.ndarray

    @property
    def translation_mm(self) -> float:
        return float(np.linalg.norm(self.T_parent_child[:3, 3]) * 1e3)

    @property
    def rotation_deg(self) -> float:
        return rotation_angle_deg(self.T_parent_child[:3, :3])

    @property
    def sigma_translation_mm(self) -> float:
        return sigma_translation_mm(self.covariance, self.T_parent_child[:3, 3])

    @property
    def sigma_rotation_deg(self) -> float:
        return sigma_rotation_deg(self.covariance)


@dataclass(frozen=True)
class RigTree:
    """Frames joined by edges into one tree under ``root``."""

    root: str
    edges: tuple[Edge, ...]

    def __post_init__(self) -> None:
        seen = {self.root}
        for edge in self.edges:  # parents come first, every child once: a tree by construction
            if edge.parent not in seen or edge.child in seen:
                raise ValueError(f"edge {edge.parent} -> {edge.child} does not extend the tree")
            seen.add(edge.child)

    @property
    def frames(self) -> tuple[str, ...]:
        return (self.root, *(e.child for e in self.edges))

    def T_root(self, frame: str) -> np.ndarray:
        """(4, 4) T_root_frame along the tree's one path."""
        by_child = {e.child: e for e in self.edges}
        T = np.eye(4)
        while frame != self.root:
            edge = by_child[frame]
            T = edge.T_parent_child @ T
            frame = edge.parent
        return T

    def T(self, a: str, b: str) -> np.ndarray:
        """(4, 4) T_a_b between any two frames."""
        return invert(self.T_root(a)) @ self.T_root(b)


def inverted(edge: Edge) -> Edge:
    """The same edge seen from the child: T_child_parent with its covariance carried through."""
    pose = T_to_pose(edge.T_parent_child)
    cov = propagate(lambda p: T_to_pose(invert(pose_to_T(p))), pose, edge.covariance)
    return Edge(edge.child, edge.parent, invert(edge.T_parent_child), cov)


def orient_tree(edges: Sequence[Edge], preferred_root: str) -> RigTree:
    """Edges measured in any direction (a rig solve's ``cam0 -> cam1``, a hand-eye ``flange -> cam0``)
    as one tree: rooted at the only frame that is nobody's child (``flange``: the tf parent a robot
    publishes), else at ``preferred_root``; an edge met from its child's side is inverted.
    Raises ValueError when the edges close a loop or do not all connect.
    """
    children = {e.child for e in edges}
    frames = list(dict.fromkeys(f for e in edges for f in (e.parent, e.child)))
    tops = [f for f in frames if f not in children]
    root = tops[0] if len(tops) == 1 else preferred_root
    seen, out, pending = {root}, [], list(edges)
    while pending:
        nxt = next((e for e in pending if (e.parent in seen) != (e.child in seen)), None)
        if nxt is None:
            closing = next((e for e in pending if e.parent in seen), pending[0])
            why = "closes a loop" if closing.parent in seen else f"does not connect to {root}"
            raise ValueError(f"edge {closing.parent} -> {closing.child} {why}")
        pending.remove(nxt)
        out.append(nxt if nxt.parent in seen else inverted(nxt))
        seen.add(out[-1].child)
    return RigTree(root, tuple(out))


def simple_cycles(nodes: Sequence[int], edges: set[frozenset[int]]) -> list[tuple[int, ...]]:
    """Every simple cycle (length >= 3) of an undirected graph, each once, starting at its smallest node."""
    adjacency = {n: sorted(m for e in edges if n in e for m in e if m != n) for n in nodes}
    cycles: list[tuple[int, ...]] = []

    def walk(path: list[int]) -> None:
        for nxt in adjacency[path[-1]]:
            if nxt == path[0] and len(path) >= 3 and path[1] < path[-1]:
                cycles.append(tuple(path))
            elif nxt > path[0] and nxt not in path:
                walk([*path, nxt])

    for start in sorted(nodes):
        walk([start])
    return cycles
