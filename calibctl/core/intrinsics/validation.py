"""Held-out validation of an intrinsic solve: k-fold over views, residuals by ring and octant.

Fold assignment: view i goes to fold i % k with k = min(5, V), raised towards leave-one-out when a
training set would fall below the model's minimum view count. Interleaving (rather than contiguous
blocks) spreads a capture that sweeps the board across the image over all folds. Deterministic.

For each fold the model is solved on the other folds' views; each held-out view's board pose is then
re-fitted with cv2.solvePnP (SOLVEPNP_ITERATIVE) with K and distortion frozen, and its residuals
collected. Held-out residuals are therefore honest about the intrinsics and optimistic only by the
6 pose parameters fitted per view, exactly like the fit residuals of the same view.

The folds are independent, so they are solved on the caller's lanes (``core.lanes``: the workflow's pool,
bounded by ``--jobs``; cv2 releases the GIL; no lanes: one after another). Every solve runs with OpenCV
and BLAS single-threaded (``single_threaded_opencv``; the pool's owner enters it once around the pool
because cv2.setNumThreads is process-global), so each fold's result is bit-identical to a sequential
run whatever the scheduling (tests/core/intrinsics/test_validation.py checks it). numpy's OpenBLAS on
one thread matters: its spinning worker thread otherwise takes the second core and 2 threads are slower
than 1. 20 views at 1280x960 on the 2-core bench machine: 140-180 ms sequential, 81-96 ms on 2 threads
(benchmarks/bench_e2e.py stage profile: benchmarks/results/end-to-end.md).

Radius rings ("quintiles"): the radius of a corner is the distance of its OBSERVED pixel position
from the principal point of the full-data fit. The ring edges are the 20/40/60/80 % quantiles of
those radii over all corners of the session, computed once and applied to both the fit and the
held-out residuals, so "outer ring" is the same set of corners in both numbers and always holds a
fifth of the data. Fixed geometric rings (e.g. r > 0.8 of the half-diagonal) were rejected: most
sessions put few or no corners there, which makes the outer-ring RMS and the held-out/fit ratio
noise, or undefined, and the lint gate on it flaky. The price: the outer ring is relative to the
session's own coverage; whether the board reached the image corners at all is the capture gate's
job (coverage), not this number's.

Octants: angle of (u - W/2, v - H/2) around the IMAGE centre, octant 0 = [0, 45) deg from +u
towards +v (image down), counting clockwise on screen.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.solve import (
    IntrinsicsSolution,
    fit_pose,
    get_model,
    project_points,
    residual_rms_px,
    single_threaded_opencv,
    solve_intrinsics,
    starts_warm,
)
from calibctl.core.lanes import Lanes, lanes_map
from calibctl.errors import NumericalError

MAX_FOLDS = 5
N_RINGS = 5
N_OCTANTS = 8


def fold_assignment(n_views: int, min_training_views: int, max_folds: int = MAX_FOLDS) -> np.ndarray:
    """(V,) int64 fold index per view: view i -> fold i % k.

    k = min(max_folds, V), raised (up to leave-one-out) until every training set keeps
    ``min_training_views`` views.

    Raises:
        NumericalError: fewer than min_training_views + 1 views, so nothing can be held out.
    """
    if n_views < min_training_views + 1:
        raise NumericalError(
            f"held-out validation needs at least {min_training_views + 1} views, got {n_views}",
            hint="capture more views",
        )
    k = min(max_folds, n_views)
    while n_views - math.ceil(n_views / k) < min_training_views:
        k += 1  # more folds -> smaller held-out sets -> larger training sets; k = V is leave-one-out
    return np.arange(n_views, dtype=np.int64) % k


def refit_pose_residuals(
    object_points: np.ndarray,
    image_points: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str = DEFAULT_MODEL,
) -> np.ndarray:
    """Residuals of one view with intrinsics frozen and the board pose re-fitted.

    Args:
        object_points: (N, 3) float64 board frame. image_points: (N, 2) float64 px.
        camera_matrix: (3, 3) px. dist_coeffs: (n,) OpenCV order. model: a MODELS name (pinhole or
            fisheye decides the projection; the pinhole models all project alike).

    Returns:
        (N, 2) float64 observed - projected.
    """
    return refit_pose(object_points, image_points, camera_matrix, dist_coeffs, model)[0]


def refit_pose(
    object_points: np.ndarray,
    image_points: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str = DEFAULT_MODEL,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """As refit_pose_residuals, also returning the fitted pose: (residuals (N, 2) px, rvec (3,), tvec (3,)
    m)."""
    obj = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    img = np.asarray(image_points, dtype=np.float64).reshape(-1, 2)
    with single_threaded_opencv():
        pose = fit_pose(obj, img, camera_matrix, dist_coeffs, model)
        if pose is None:
            raise NumericalError("the board pose of a held-out view could not be fitted")
        proj = project_points(obj, pose[0], pose[1], camera_matrix, dist_coeffs, model)
    return img - proj, np.asarray(pose[0], np.float64).reshape(3), np.asarray(pose[1], np.float64).reshape(3)


@dataclass(frozen=True)
class ResidualBreakdown:
    """Residual RMS (px, OpenCV's per-corner definition) by radius ring and by image octant.

    Attributes:
        radius_edges_px: (4,) ring edges, px from the principal point (ring 4 = r >= edges[3]).
        ring_rms_px: (5,) inner to outer; nan for an empty ring. ring_counts: (5,) corners.
        octant_rms_px: (8,) see module docstring for the numbering. octant_counts: (8,).
    """

    radius_edges_px: np.ndarray
    ring_rms_px: np.ndarray
    ring_counts: np.ndarray
    octant_rms_px: np.ndarray
    octant_counts: np.ndarray

    @property
    def outer_rms_px(self) -> float:
        return float(self.ring_rms_px[-1])


def radius_ring_edges_px(
    image_points_per_view: Sequence[np.ndarray], principal_point_px: tuple[float, float]
) -> np.ndarray:
    """(4,) float64 radii (px from the principal point) splitting the corners into five equal rings."""
    pts = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in image_points_per_view])
    radius = np.hypot(pts[:, 0] - principal_point_px[0], pts[:, 1] - principal_point_px[1])
    return np.quantile(radius, [0.2, 0.4, 0.6, 0.8])


def residual_breakdown(
    image_points_per_view: Sequence[np.ndarray],
    residuals_px_per_view: Sequence[np.ndarray],
    principal_point_px: tuple[float, float],
    image_size: tuple[int, int],
    radius_edges_px: np.ndarray,
) -> ResidualBreakdown:
    """Split residuals by radius ring and image octant.

    Args:
        image_points_per_view: V arrays (N_i, 2) float64 observed corners, px.
        residuals_px_per_view: V arrays (N_i, 2) float64, px, matching rows.
        principal_point_px: (cx, cy) the rings are centred on.
        image_size: (width, height) px; octants are centred on the image centre.
        radius_edges_px: (4,) from radius_ring_edges_px.
    """
    pts = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in image_points_per_view])
    res = np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in residuals_px_per_view])
    radius = np.hypot(pts[:, 0] - principal_point_px[0], pts[:, 1] - principal_point_px[1])
    ring = np.searchsorted(np.asarray(radius_edges_px), radius, side="right")
    angle = np.arctan2(pts[:, 1] - image_size[1] / 2.0, pts[:, 0] - image_size[0] / 2.0)
    octant = np.floor(np.mod(angle, 2 * np.pi) / (np.pi / 4)).astype(np.int64) % N_OCTANTS
    ring_rms = np.array([residual_rms_px(res[ring == i]) for i in range(N_RINGS)])
    octant_rms = np.array([residual_rms_px(res[octant == i]) for i in range(N_OCTANTS)])
    return ResidualBreakdown(
        radius_edges_px=np.asarray(radius_edges_px, dtype=np.float64).copy(),
        ring_rms_px=ring_rms,
        ring_counts=np.bincount(ring, minlength=N_RINGS),
        octant_rms_px=octant_rms,
        octant_counts=np.bincount(octant, minlength=N_OCTANTS),
    )


@dataclass(frozen=True)
class HoldoutReport:
    """k-fold held-out validation of one model on one session.

    Attributes:
        model: DistortionModel name.
        fold_of_view: (V,) int64 fold index of each view; n_folds = max + 1.
        fold_camera_matrices: (k, 3, 3) K solved without each fold (spread = stability).
        holdout_residuals_px: V arrays (N_i, 2) float64, each view predicted by a solve without it.
        holdout_per_view_rms_px: (V,). holdout_rms_px: over all corners.
        fit_rms_px: the full-data solve's RMS (same definition).
        holdout: ResidualBreakdown of the held-out residuals. fit: the same for the fit residuals,
            same ring edges, same corners.
    """

    model: str
    fold_of_view: np.ndarray
    fold_camera_matrices: np.ndarray
    holdout_residuals_px: tuple[np.ndarray, ...]
    holdout_per_view_rms_px: np.ndarray
    holdout_rms_px: float
    fit_rms_px: float
    holdout: ResidualBreakdown
    fit: ResidualBreakdown

    @property
    def n_folds(self) -> int:
        return int(self.fold_of_view.max()) + 1

    @property
    def holdout_outer_rms_px(self) -> float:
        return self.holdout.outer_rms_px

    @property
    def fit_outer_rms_px(self) -> float:
        return self.fit.outer_rms_px

    @property
    def outer_ratio(self) -> float:
        """Held-out outer-ring RMS / fit outer-ring RMS (lint: at most 1.1)."""
        return self.holdout_outer_rms_px / self.fit_outer_rms_px


def validate_holdout(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: str,
    fit: IntrinsicsSolution | None = None,
    initial: np.ndarray | None = None,
    max_folds: int = MAX_FOLDS,
    ring_centre_px: tuple[float, float] | None = None,
    lanes: Lanes | None = None,
    warm: bool = False,
) -> HoldoutReport:
    """k-fold held-out validation over views.

    Args:
        object_points_per_view, image_points_per_view, image_size, model, initial: as solve_intrinsics.
        fit: the full-data solve of the same views and model, when already computed.
        max_folds: upper bound on k.
        ring_centre_px: centre of the radius rings; default the fit's principal point. Pass the
            same centre when comparing models so their outer rings hold the same corners.
        lanes: where the folds are solved (core.lanes); the result does not depend on it (None: sequentially).
        warm: each fold starts from the fit's K and distortion (CALIB_USE_INTRINSIC_GUESS), not from
            ``initial`` or OpenCV's closed-form start: the same minimum, a fold's solve about a quarter
            cheaper (benchmarks/bench_warm_folds.py). Only where the folds need not find the minimum on
            their own: agree_with_folds relies on cold folds to catch a fit stopped in a worse minimum.
            Ignored where the warm start may find another minimum (solve.starts_warm: rational, fisheye).

    Raises:
        NumericalError: too few views to hold any out, or a fold's solve fails (names the fold).
    """
    m = get_model(model)
    if fit is None:
        fit = solve_intrinsics(object_points_per_view, image_points_per_view, image_size, m.name, initial)
    n_views = len(image_points_per_view)
    if fit.n_views != n_views:
        raise ValueError(f"the fit has {fit.n_views} views but {n_views} were given")
    folds = fold_assignment(n_views, m.min_views, max_folds)
    start_K, start_D = initial, None
    if warm and starts_warm(m.name):
        start_K, start_D = np.asarray(fit.camera_matrix), np.asarray(fit.dist_coeffs)

    def solve_fold(f: int) -> tuple[np.ndarray, dict[int, np.ndarray]]:
        """(K solved without fold f, {held-out view: its residuals})."""
        train = np.flatnonzero(folds != f).tolist()
        held = np.flatnonzero(folds == f).tolist()
        try:
            sol = solve_intrinsics(
                [object_points_per_view[i] for i in train],
                [image_points_per_view[i] for i in train],
                image_size,
                m.name,
                start_K,
                uncertainty=False,
                initial_dist=start_D,
            )
        except NumericalError as exc:
            raise NumericalError(
                f"held-out fold {f} (views {held} held out): {exc.message}", hint=exc.hint
            ) from exc
        return sol.camera_matrix, {
            i: refit_pose_residuals(
                object_points_per_view[i],
                image_points_per_view[i],
                sol.camera_matrix,
                sol.dist_coeffs,
                m.name,
            )
            for i in held
        }

    holdout: list[np.ndarray] = [np.empty((0, 2))] * n_views
    fold_K = []
    # results come in fold order, so a failure names the same (lowest) fold as a sequential loop would
    with single_threaded_opencv():
        for K, residuals in lanes_map(lanes, solve_fold, range(int(folds.max()) + 1)):
            fold_K.append(K)
            for i, r in residuals.items():
                holdout[i] = r
    pp = (fit.cx, fit.cy) if ring_centre_px is None else ring_centre_px
    edges = radius_ring_edges_px(image_points_per_view, pp)
    all_holdout = np.concatenate(holdout)
    return HoldoutReport(
        model=m.name,
        fold_of_view=folds,
        fold_camera_matrices=np.stack(fold_K),
        holdout_residuals_px=tuple(holdout),
        holdout_per_view_rms_px=np.array([residual_rms_px(r) for r in holdout]),
        holdout_rms_px=residual_rms_px(all_holdout),
        fit_rms_px=fit.rms_px,
        holdout=residual_breakdown(image_points_per_view, holdout, pp, image_size, edges),
        fit=residual_breakdown(image_points_per_view, fit.residuals_px, pp, image_size, edges),
    )


# A held-out RMS below the fit's by more than this fraction means the folds found a better minimum.
FOLD_MINIMUM_SLACK = 0.05


def agree_with_folds(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    fit: IntrinsicsSolution,
    report: HoldoutReport,
    lanes: Lanes | None = None,
) -> tuple[IntrinsicsSolution, HoldoutReport]:
    """The full solve and its held-out numbers from the same minimum, or a NumericalError.

    Held-out residuals are never expected below the fit's: when they are (by FOLD_MINIMUM_SLACK), the
    full solve stopped in a worse minimum than its folds. It is re-solved from the folds' median K and
    validated again; if the fit is still worse than its folds, the solve is refused with both numbers.
    """
    if fit.rms_px <= (1.0 + FOLD_MINIMUM_SLACK) * report.holdout_rms_px:
        return fit, report
    start = np.median(report.fold_camera_matrices, axis=0)
    start[0, 1] = start[1, 0] = start[2, 0] = start[2, 1] = 0.0
    start[2, 2] = 1.0
    resolved = solve_intrinsics(object_points_per_view, image_points_per_view, image_size, fit.model, start)
    if resolved.rms_px < fit.rms_px:
        fit = resolved
        report = validate_holdout(
            object_points_per_view,
            image_points_per_view,
            image_size,
            fit.model,
            fit=fit,
            initial=start,
            lanes=lanes,
        )
    if fit.rms_px > (1.0 + FOLD_MINIMUM_SLACK) * report.holdout_rms_px:
        raise NumericalError(
            f"model {fit.model}: the full solve (fit RMS {fit.rms_px:.3f} px) is worse than its held-out "
            "folds "
            f"({report.holdout_rms_px:.3f} px) even from the folds' intrinsics: they belong to different "
            "minima",
            hint=(
                "capture more views tilted 20-40 deg covering the image, or --model fisheye for a wide lens"
                if fit.model == "k1k2"
                # never "fewer coefficients (k1k2)" to a k1k2 solve
                else "solve with a model with fewer coefficients (--model k1k2), or --model fisheye for a "
                "wide lens"
            ),
        )
    return fit, report
