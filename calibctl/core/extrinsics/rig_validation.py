"""Held-out validation of a rig solve (k-fold over synchronised frames) and loop closure.

Held-out: frames go to folds by ``core.intrinsics.validation.fold_assignment`` (frame i -> fold i % k). For
each fold the rig is re-solved on the other frames; each held-out frame's board pose T_root_board is then
fitted jointly to every camera's corners with the extrinsics and intrinsics frozen (Levenberg-Marquardt
on 6 parameters, calibctl.core.lm), so a wrong extrinsic shows up as residual in some camera instead of
being absorbed by a per-camera pose. Per camera: held-out reprojection RMS. Per pair: epipolar error and
rectified cross-epipolar disparity (rig_metrics) of the held-out frames both cameras saw.

Loop closure (3+ cameras): every pair with shared frames is solved on its own (a 2-camera solve);
around every simple cycle of that pair graph the composed transform should be identity. The residual
(rotation deg, translation mm) is reported with its one-sigma and the Mahalanobis distance of the 6-vector,
both from the loop's Jacobian covariance with the cross covariances of pairs that share a camera's corners
(core.extrinsics.rig_loop; treated as independent they read the loop several times too wide). A joint solve
closes its own loops by construction; the pairwise loop is the rig's health metric (seed ch. 6 prompt B).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.blas_threads import single_threaded
from calibctl.core.extrinsics.rig_init import view_poses
from calibctl.core.extrinsics.rig_loop import loop_covariance
from calibctl.core.extrinsics.rig_metrics import epipolar_distances_px, rectified_cross_disparity_px, rectify
from calibctl.core.extrinsics.rig_problem import Layout, MemberIntrinsics, RigViews, normal_equations
from calibctl.core.extrinsics.rig_solve import RigSolution, shared_corners_only, solve_rig
from calibctl.core.extrinsics.rig_tree import T_to_pose, pose_to_T, simple_cycles
from calibctl.core.extrinsics.se3 import invert, rotation_angle_deg
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.validation import fold_assignment
from calibctl.core.lm import DenseSystem, solve_lm
from calibctl.errors import InconsistentDataError, NumericalError

MIN_TRAINING_FRAMES = 4
POSE_FIT_ITERATIONS = 20
POSE_FIT_TOLERANCE = 1e-12  # relative fall of the residual sum below which a pose step only chases rounding
POSE_FIT_STEP = 1e-12  # rad / m: a smaller step only chases rounding
MIN_PAIR_FRAMES = 3  # a pair enters the loop-closure graph with at least this many shared frames


@dataclass(frozen=True)
class PairHoldout:
    """Held-out geometry of one pair (a < b, camera indices)."""

    a: int
    b: int
    n_frames: int
    epipolar_rms_px: float
    epipolar_max_px: float
    rectified_rms_px: float
    rectified_max_px: float


@dataclass(frozen=True)
class RigHoldout:
    n_folds: int
    camera_rms_px: tuple[float, ...]
    pairs: tuple[PairHoldout, ...]


@dataclass(frozen=True)
class LoopClosure:
    cycle: tuple[str, ...]
    rotation_deg: float
    translation_mm: float
    sigma_rotation_deg: float
    sigma_translation_mm: float
    mahalanobis: float


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def fit_board_pose(
    views: RigViews, f: int, members: Sequence[MemberIntrinsics], cam_poses: np.ndarray
) -> np.ndarray:
    """(6,) T_root_board of frame f fitted to every camera's corners, extrinsics frozen (calibctl.core.lm,
    dense)."""
    frame = views.subset([f])
    start = view_poses(frame, members)
    c, T_cam_board = next(iter((k[1], v) for k, v in start.items()))
    pose = T_to_pose(invert(pose_to_T(cam_poses[c])) @ T_cam_board)
    layout = Layout(len(views.cameras), 1, tuple(m.n_params for m in members))
    idx = layout.board(0)

    def evaluate(pose: np.ndarray) -> DenseSystem:
        ne = normal_equations(frame, members, cam_poses, pose[None, :], layout)
        return DenseSystem(ne.ssr, ne.H[np.ix_(idx, idx)], ne.g[idx])

    return solve_lm(
        evaluate,
        pose,
        lambda p, d: p + d,
        max_iterations=POSE_FIT_ITERATIONS,
        relative_tolerance=POSE_FIT_TOLERANCE,
        step_tolerance=POSE_FIT_STEP,
        label=f"the held-out board pose of frame {f}",
    ).params


def validate_rig_holdout(
    views: RigViews,
    members: Sequence[MemberIntrinsics],
    refine_intrinsics: bool = False,
    model: str = DEFAULT_MODEL,
    solver: str = "auto",
) -> RigHoldout:
    """k-fold held-out numbers (see module docstring).

    Raises:
        NumericalError: too few frames to hold any out, or no fold could be solved.
    """
    with single_threaded():  # folds and board-pose fits run one after another: spare threads only spin
        return _validate_rig_holdout(views, members, refine_intrinsics, model, solver)


def _validate_rig_holdout(
    views: RigViews, members: Sequence[MemberIntrinsics], refine_intrinsics: bool, model: str, solver: str
) -> RigHoldout:
    views = shared_corners_only(views)
    folds = fold_assignment(len(views.frames), MIN_TRAINING_FRAMES)
    n_cams = len(views.cameras)
    cam_res: list[list[np.ndarray]] = [[] for _ in range(n_cams)]
    epi: dict[tuple[int, int], list[np.ndarray]] = {}
    rect: dict[tuple[int, int], list[np.ndarray]] = {}
    frames_of: dict[tuple[int, int], int] = {}
    solved = 0
    for k in range(int(folds.max()) + 1):
        held = np.flatnonzero(folds == k)
        try:
            fit = solve_rig(
                views.subset(np.flatnonzero(folds != k).tolist()), members, refine_intrinsics, model, solver
            )
        except (NumericalError, InconsistentDataError):
            continue  # this fold's training frames do not solve the rig; the others still count
        solved += 1
        layout = Layout(n_cams, 1, tuple(m.n_params for m in fit.members))
        rectifications = {
            (a, b): rectify(fit.members[a], fit.members[b], fit.T_a_b(b, a))
            for a in range(n_cams)
            for b in range(a + 1, n_cams)
        }
        for f in held:
            pose = fit_board_pose(views, int(f), fit.members, fit.cam_poses)
            ne = normal_equations(views.subset([int(f)]), fit.members, fit.cam_poses, pose[None, :], layout)
            for (_, c), res in ne.residuals_px.items():
                cam_res[c].append(np.sum(res**2, axis=1))
            row = views.views[int(f)]
            for (a, b), rectification in rectifications.items():
                va, vb = row[a], row[b]
                if va is None or vb is None:
                    continue
                common, ia, ib = np.intersect1d(va.corner_ids, vb.corner_ids, return_indices=True)
                if common.size == 0:
                    continue
                pa, pb = va.corners_px[ia], vb.corners_px[ib]
                ma, mb = fit.members[a], fit.members[b]
                epi.setdefault((a, b), []).append(epipolar_distances_px(pa, pb, ma, mb, fit.T_a_b(b, a)))
                rect.setdefault((a, b), []).append(
                    rectified_cross_disparity_px(pa, pb, ma, mb, rectification)
                )
                frames_of[(a, b)] = frames_of.get((a, b), 0) + 1
    if solved == 0:
        raise NumericalError(
            "no held-out fold could be solved: the rig is not connected without the held-out frames",
            hint="capture more frames that pairs of cameras see together",
        )
    camera_rms = tuple(float(np.sqrt(np.mean(np.concatenate(r)))) if r else float("nan") for r in cam_res)
    pairs = []
    for (a, b), d in sorted(epi.items()):
        e, r = np.concatenate(d), np.concatenate(rect[(a, b)])
        pairs.append(
            PairHoldout(a, b, frames_of[(a, b)], _rms(e), float(np.max(e)), _rms(r), float(np.max(np.abs(r))))
        )
    return RigHoldout(solved, camera_rms, tuple(pairs))


def pairwise_solutions(
    views: RigViews,
    members: Sequence[MemberIntrinsics],
    model: str = DEFAULT_MODEL,
    min_frames: int = MIN_PAIR_FRAMES,
) -> dict[tuple[int, int], RigSolution]:
    """Independent 2-camera solves of every pair (a < b) with at least ``min_frames`` shared frames."""
    out = {}
    for (a, b), count in views.shared_view_counts().items():
        if count < min_frames:
            continue
        frames = [i for i, row in enumerate(views.views) if row[a] is not None and row[b] is not None]
        pair = RigViews(
            (views.cameras[a], views.cameras[b]),
            views.model_points_m,
            tuple(views.frames[i] for i in frames),
            tuple((views.views[i][a], views.views[i][b]) for i in frames),
        )
        out[(a, b)] = solve_rig(pair, (members[a], members[b]), model=model)
    return out


def loop_closures(
    views: RigViews, members: Sequence[MemberIntrinsics], model: str = DEFAULT_MODEL
) -> tuple[LoopClosure, ...]:
    """Residual around every simple cycle of the pairwise-solved camera graph (empty for 2 cameras), judged by
    the loop's covariance with the pairs' cross covariances (core.extrinsics.rig_loop)."""
    with single_threaded():  # pair solves and loop covariances run one after another: spare threads only spin
        return _loop_closures(views, members, model)


def _loop_closures(
    views: RigViews, members: Sequence[MemberIntrinsics], model: str
) -> tuple[LoopClosure, ...]:
    pairs = pairwise_solutions(views, members, model)
    edges = {frozenset(p) for p in pairs}
    out = []
    for cycle in simple_cycles(range(len(views.cameras)), edges):
        hops = list(zip(cycle, (*cycle[1:], cycle[0]), strict=True))
        # x: each hop's pair estimate cam_poses[1], the pose of T_hi_lo; the hop a -> b reads T_a_b from it
        solutions = [pairs[(min(a, b), max(a, b))] for a, b in hops]
        x = np.concatenate([sol.cam_poses[1] for sol in solutions])
        forward = [a < b for a, b in hops]

        def around(v: np.ndarray, forward: list[bool] = forward) -> np.ndarray:
            T = np.eye(4)
            for p, fwd in zip(np.split(v, len(forward)), forward, strict=True):
                T = T @ (invert(pose_to_T(p)) if fwd else pose_to_T(p))
            return T_to_pose(T)

        r = around(x)
        cov_r = loop_covariance(solutions, views, around, x).jacobian
        T = pose_to_T(r)
        out.append(
            LoopClosure(
                tuple(views.cameras[i] for i in cycle),
                rotation_angle_deg(T[:3, :3]),
                float(np.linalg.norm(r[3:]) * 1e3),
                float(np.rad2deg(np.sqrt(np.trace(cov_r[:3, :3])))),
                float(np.sqrt(np.trace(cov_r[3:, 3:])) * 1e3),
                float(np.sqrt(r @ np.linalg.solve(cov_r, r))),
            )
        )
    return tuple(out)
