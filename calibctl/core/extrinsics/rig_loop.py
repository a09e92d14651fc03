"""Joint covariance of pairwise rig solves that share corners: what a loop-closure residual is judged by.

Pairs (a, b) and (a, c) of one rig are solved on their own but read the same corners of camera a in the frames
all three saw (and the same intrinsics of a): their errors are correlated, and around a loop much of camera
a's error cancels. Treated as independent, the loop's covariance is several times too wide (Mahalanobis
0.17-0.67 on clean rendered 3-4 camera rigs) and the rule fires only on gross errors.

Joint linearisation (first order, no re-solve): each pair's estimate x_p (the pose vector of T_b_a, its
cam_poses[1]) moves by G_p r for residuals r, G_p = [H_p^-1]_(x, obs) J_obs^T per (frame, camera) block, the
board pose of that frame eliminated as in the pair's own solve (core.extrinsics.rig_uncertainty.linearise).
Two pairs share the corners of one camera in one frame with the same corner id, so

    Cov_jac(x_p, x_q) = s_p s_q sum_(shared corners) G_p G_q^T + A_p Cov_theta A_q^T (members held fixed)

(on p = q the pair's own Jacobian covariance). The frame-level side pairs the pulls of the clusters both pairs
hold (a frame, or a member's photo): Cov_frame(x_p, x_q) = c_pq sum_k (P_pk - mean_p)(P_qk - mean_q)^T, c_pq =
sqrt((n_p - 1)/n_p (n_q - 1)/n_q) (on p = q the pair's own jackknife). The loop residual's covariance is
either propagated to first order. The rule judges the Jacobian one: a broken loop is a per-frame inconsistency
(some frames of one pair disagree with the rest), which the frame-level covariance takes for frame-level error
and absorbs (a 3 px break on corner-level rigs reads d 2.4 with it, 9 with the Jacobian one; per-component
scaling as for a rig's own sigma also undoes the cancellation around the loop). Measured in docs/verdicts.md
(benchmarks/bench_rig_loop.py).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics.rig_problem import RigViews, observation_jacobian
from calibctl.core.extrinsics.rig_solve import RigSolution
from calibctl.core.extrinsics.rig_tree import propagate
from calibctl.core.extrinsics.rig_uncertainty import MIN_FRAMES, RigLinearisation, linearise

Cluster = str | tuple[str, str]


@dataclass(frozen=True)
class _Pair:
    """One pair solve linearised: its corner gains, cluster pulls and intrinsic gains over x =
    cam_poses[1]."""

    cameras: tuple[str, str]
    gains: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]]  # (frame, camera) -> ids (N,), s G (6, N, 2)
    pulls: dict[Cluster, np.ndarray]  # cluster -> (6,), centred on the pair's mean
    jackknife_factor: float  # (n - 1) / n
    theta: dict[
        str, tuple[np.ndarray, np.ndarray, np.ndarray]
    ]  # camera -> A (6, p), Cov_jac (p, p), Cov_unknown


@dataclass(frozen=True)
class LoopCovariance:
    """(6, 6) covariances of a loop residual (rvec rad, tvec m): the Jacobian one (the rule's), the
    frame-level one (None under MIN_FRAMES clusters in some pair; not judged, module docstring)."""

    jacobian: np.ndarray
    frame_level: np.ndarray | None


def _linearised_pair(sol: RigSolution, full: RigViews) -> _Pair:
    """Gains and pulls of a 2-camera solve, its clusters named as in the rig ``full``."""
    views, members = sol.views, sol.members
    lin: RigLinearisation = linearise(views, members, sol.cam_poses, sol.board_poses, False)
    layout, x = lin.layout, np.arange(6)
    s = np.sqrt(lin.residual_variance_px2)
    gains = {}
    for f, row in enumerate(views.views):
        for c, view in enumerate(row):
            if view is None:
                continue
            obj = view.object_points(views.model_points_m)
            _, J_board, J_cam, _ = observation_jacobian(
                obj, sol.cam_poses[c] if c > 0 else None, sol.board_poses[f], members[c]
            )
            cols, J = (
                (layout.board(f), J_board)
                if J_cam is None
                else (np.concatenate([layout.ext(c), layout.board(f)]), np.hstack([J_cam, J_board]))
            )
            G = s * lin.H_inv[np.ix_(x, cols)] @ J.T
            gains[(views.frames[f], views.cameras[c])] = (np.asarray(view.corner_ids), G.reshape(6, -1, 2))
    photo_frame = {
        (full.cameras[c], v.name): full.frames[f]
        for f, row in enumerate(full.views)
        for c, v in enumerate(row)
        if v is not None
    }
    keyed = {(photo_frame.get(k, k) if isinstance(k, tuple) else k): p[:6] for k, p in lin.pulls.items()}
    mean = np.mean(list(keyed.values()), axis=0)
    n = len(keyed)
    theta = {}
    if lin.intrinsic_gain is not None:
        assert lin.cov_theta_jacobian is not None and lin.cov_theta_unknown is not None
        fixed0 = layout.board0 + 6 * layout.n_frames
        for c, name in enumerate(views.cameras):
            at = layout.intrinsics(c) - fixed0
            theta[name] = (
                lin.intrinsic_gain[np.ix_(x, at)],
                lin.cov_theta_jacobian[np.ix_(at, at)],
                lin.cov_theta_unknown[np.ix_(at, at)],
            )
    return _Pair(
        (views.cameras[0], views.cameras[1]),
        gains,
        {k: p - mean for k, p in keyed.items()},
        (n - 1) / n if n >= MIN_FRAMES else float("nan"),
        theta,
    )


def _cross(p: _Pair, q: _Pair) -> tuple[np.ndarray, np.ndarray]:
    """(6, 6) Jacobian and frame-level Cov(x_p, x_q) (module docstring)."""
    jac, frame = np.zeros((6, 6)), np.zeros((6, 6))
    for key, (ids_p, G_p) in p.gains.items():
        if key not in q.gains:
            continue
        ids_q, G_q = q.gains[key]
        _, ia, ib = np.intersect1d(ids_p, ids_q, return_indices=True)
        jac += np.einsum("inc,jnc->ij", G_p[:, ia], G_q[:, ib])
    for cam in set(p.theta) & set(q.theta):
        (A_p, cov_jac, cov_unknown), A_q = p.theta[cam], q.theta[cam][0]
        jac += A_p @ cov_jac @ A_q.T
        frame += A_p @ cov_unknown @ A_q.T
    for cluster in set(p.pulls) & set(q.pulls):
        frame += np.sqrt(p.jackknife_factor * q.jackknife_factor) * np.outer(
            p.pulls[cluster], q.pulls[cluster]
        )
    return jac, frame


def loop_covariance(
    pair_solutions: Sequence[RigSolution],
    full: RigViews,
    around: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
) -> LoopCovariance:
    """Covariances of ``around(x)``, x the stacked cam_poses[1] of ``pair_solutions`` (2-camera RigSolutions
    of the rig ``full``), with every cross covariance between the pairs (module docstring)."""
    pairs = [_linearised_pair(sol, full) for sol in pair_solutions]
    k = len(pairs)
    jac, frame = np.zeros((6 * k, 6 * k)), np.zeros((6 * k, 6 * k))
    for i, p in enumerate(pairs):
        for j in range(i, k):
            cj, cf = _cross(p, pairs[j])
            jac[6 * i : 6 * i + 6, 6 * j : 6 * j + 6], frame[6 * i : 6 * i + 6, 6 * j : 6 * j + 6] = cj, cf
            jac[6 * j : 6 * j + 6, 6 * i : 6 * i + 6], frame[6 * j : 6 * j + 6, 6 * i : 6 * i + 6] = (
                cj.T,
                cf.T,
            )
    cov_jac = propagate(around, x, jac)
    if not all(np.isfinite(p.jackknife_factor) for p in pairs):
        return LoopCovariance(cov_jac, None)
    return LoopCovariance(cov_jac, propagate(around, x, frame))
