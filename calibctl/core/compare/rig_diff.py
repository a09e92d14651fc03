"""Two versions of a rig's extrinsics: what moved between each pair of cameras, beyond both covariances.

For each camera pair (a, b), T_a_b is read off each version's tree (``RigTree.T``); its change is
dr = rotvec(R_a_b(B) R_a_b(A)^T) (rad, a's frame) and dt = t_a_b(B) - t_a_b(A) (m, a's frame: where b's
centre moved), with the baseline change |t(B)| - |t(A)|. Every number's covariance is carried from the
two versions' edge covariances (independent solves) by ``rig_tree.propagate`` over the stacked edge
poses of both trees, so the path through the tree and every edge on it count.

The test of a pair: the 6-vector (dr, dt) against its covariance, chi2(6); each pair at ALPHA / pairs
(Bonferroni), so an unchanged rig is flagged with at most ALPHA probability when the stored covariances
are honest.

Depth-error change (the stereo number Luxonis' health check reports): a point on the bisector between
the two optical centres at depth Z in front of camera a, seen through version B's extrinsics (taken as
the truth), is triangulated with version A's; dZ = Z_A - Z. Intrinsics are held at each version's K
(the camera diff covers them), so this is the extrinsic part: baseline scale (dZ/Z = dB/B) and the
rotation about the axis normal to the baseline and the optical axis (dZ ~ Z^2 dtheta / B), exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.compare.chi2 import chi2_quantile, chi2_sf
from calibctl.core.extrinsics.rig_tree import Edge, RigTree, T_to_pose, pose_to_T, propagate, rotation_vector

DEPTHS_M = (1.0, 2.0, 5.0, 10.0)
ALPHA = 0.01


@dataclass(frozen=True)
class DepthChange:
    """dZ (m) of a point at depth_m triangulated with A's extrinsics when B's hold, and its one-sigma."""

    depth_m: float
    error_m: float
    sigma_m: float


@dataclass(frozen=True)
class PairChange:
    """How T_a_b changed from version A to version B.

    rotation_deg and its sigma (least certain axis, deg); translation_mm = |dt| and its sigma along dt;
    baseline_mm = |t(B)| - |t(A)| with sigma; mahalanobis = sqrt(chi2) of (dr, dt) with 6 dof; p_value.
    """

    a: str
    b: str
    baseline_a_mm: float
    baseline_b_mm: float
    baseline_change_mm: float
    sigma_baseline_change_mm: float
    rotation_deg: float
    sigma_rotation_deg: float
    translation_mm: float
    sigma_translation_mm: float
    chi2: float
    p_value: float
    threshold: float
    significant: bool
    depth: tuple[DepthChange, ...]


def _stack(tree: RigTree) -> tuple[np.ndarray, np.ndarray]:
    poses = np.concatenate([T_to_pose(e.T_parent_child) for e in tree.edges])
    cov = np.zeros((len(poses), len(poses)))
    for i, e in enumerate(tree.edges):
        cov[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = e.covariance
    return poses, cov


def _rebuilt(tree: RigTree, poses: np.ndarray) -> RigTree:
    return RigTree(
        tree.root,
        tuple(
            Edge(e.parent, e.child, pose_to_T(poses[6 * i : 6 * i + 6]), e.covariance)
            for i, e in enumerate(tree.edges)
        ),
    )


def _depth_m(T_a_b_truth: np.ndarray, T_a_b_used: np.ndarray, depth_m: float) -> float:
    """Depth of the bisector point at ``depth_m`` (a's frame) seen through the truth, triangulated with
    ``used`` (midpoint of the two rays' closest approach)."""
    centre_b = T_a_b_truth[:3, 3]
    point = np.array([centre_b[0] / 2.0, centre_b[1] / 2.0, depth_m])
    ray_a = point / np.linalg.norm(point)
    ray_b_local = T_a_b_truth[:3, :3].T @ (point - centre_b)  # direction in b's frame, what b measures
    o_b = T_a_b_used[:3, 3]
    ray_b = T_a_b_used[:3, :3] @ ray_b_local
    ray_b /= np.linalg.norm(ray_b)
    w = -o_b  # closest approach of o_a + s ray_a and o_b + u ray_b (o_a = 0)
    a_, b_, c_ = ray_a @ ray_a, ray_a @ ray_b, ray_b @ ray_b
    d_, e_ = ray_a @ w, ray_b @ w
    den = a_ * c_ - b_ * b_
    s = (b_ * e_ - c_ * d_) / den
    u = (a_ * e_ - b_ * d_) / den
    mid = 0.5 * (s * ray_a + o_b + u * ray_b)
    return float(mid[2])


def camera_pairs(tree_a: RigTree, tree_b: RigTree, cameras: Sequence[str]) -> list[tuple[str, str]]:
    """Every pair of ``cameras`` present in both trees, in that order (a before b)."""
    common = [c for c in cameras if c in tree_a.frames and c in tree_b.frames]
    return [(a, b) for i, a in enumerate(common) for b in common[i + 1 :]]


def pair_changes(
    tree_a: RigTree,
    tree_b: RigTree,
    pairs: Sequence[tuple[str, str]],
    alpha: float = ALPHA,
    depths_m: Sequence[float] = DEPTHS_M,
    no_depth: Sequence[tuple[str, str]] = (),
) -> list[PairChange]:
    """The change of T_a_b for each (a, b) of ``pairs`` (frames of both trees); the depth error is left out
    for the pairs in ``no_depth`` (a hand-eye edge joins a camera to a flange, not a stereo pair).
    Each pair is tested at alpha / len(pairs)."""
    pa, ca = _stack(tree_a)
    pb, cb = _stack(tree_b)
    x = np.concatenate([pa, pb])
    cov = np.zeros((len(x), len(x)))
    cov[: len(pa), : len(pa)], cov[len(pa) :, len(pa) :] = ca, cb
    level = alpha / max(len(pairs), 1)
    out = []
    for a, b in pairs:

        def T_pair(v: np.ndarray, a: str = a, b: str = b) -> tuple[np.ndarray, np.ndarray]:
            return _rebuilt(tree_a, v[: len(pa)]).T(a, b), _rebuilt(tree_b, v[len(pa) :]).T(a, b)

        def change(v: np.ndarray) -> np.ndarray:
            Ta, Tb = T_pair(v)
            return np.concatenate([rotation_vector(Tb[:3, :3] @ Ta[:3, :3].T), Tb[:3, 3] - Ta[:3, 3]])

        def baseline(v: np.ndarray) -> np.ndarray:
            Ta, Tb = T_pair(v)
            return np.array([np.linalg.norm(Tb[:3, 3]) - np.linalg.norm(Ta[:3, 3])])

        Ta, Tb = T_pair(x)
        d = change(x)
        C = propagate(change, x, cov)
        stat = float(d @ np.linalg.pinv(C, rcond=1e-12, hermitian=True) @ d)
        rot_deg = float(np.rad2deg(np.linalg.norm(d[:3])))
        sig_rot = float(np.rad2deg(np.sqrt(max(np.linalg.eigvalsh(C[:3, :3])[-1], 0.0))))
        t_norm = float(np.linalg.norm(d[3:]))
        g = d[3:] / t_norm if t_norm > 0 else np.array([1.0, 0.0, 0.0])
        sig_t = float(np.sqrt(max(g @ C[3:, 3:] @ g, 0.0)))
        sig_base = float(np.sqrt(propagate(baseline, x, cov)[0, 0]))
        depth = []
        for z in () if (a, b) in no_depth else depths_m:

            def dz(v: np.ndarray, z: float = z) -> np.ndarray:
                Ta_v, Tb_v = T_pair(v)
                return np.array([_depth_m(Tb_v, Ta_v, z) - z])

            depth.append(
                DepthChange(z, float(dz(x)[0]), float(math.sqrt(max(propagate(dz, x, cov)[0, 0], 0.0))))
            )
        p = chi2_sf(stat, 6)
        out.append(
            PairChange(
                a,
                b,
                float(np.linalg.norm(Ta[:3, 3]) * 1e3),
                float(np.linalg.norm(Tb[:3, 3]) * 1e3),
                float(baseline(x)[0] * 1e3),
                sig_base * 1e3,
                rot_deg,
                sig_rot,
                t_norm * 1e3,
                sig_t * 1e3,
                stat,
                p,
                chi2_quantile(1.0 - level, 6),
                p < level,
                tuple(depth),
            )
        )
    return out
