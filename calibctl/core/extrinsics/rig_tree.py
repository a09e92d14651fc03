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
    R = np.asarray(R, dtype=np.float64)[:3, :3]
    w = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # sin(angle) * axis
    s, c = float(np.linalg.norm(w)), 0.5 * (float(np.trace(R)) - 1.0)
    if c < -0.99:  # near 180 deg the antisymmetric part vanishes; OpenCV's branch handles it
        return np.asarray(cv2.Rodrigues(R)[0]).reshape(3)
    return w if s < 1e-15 else w * (np.arctan2(s, c) / s)


def T_to_pose(T: np.ndarray) -> np.ndarray:
    """(4, 4) T -> (6,) float64 rvec (rad), tvec (m)."""
    T = np.asarray(T, dtype=np.float64)
    return np.concatenate([rotation_vector(T[:3, :3]), T[:3, 3]])


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid (4, 4) transform."""
    T = np.asarray(T, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a (3, 3) rotation, degrees (0..180)."""
    return float(np.rad2deg(np.linalg.norm(rotation_vector(R))))


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
