"""Outlier views and outlier corners of a solve, and the re-solve without the outlier views.

Both rules are robust (median and MAD), so one bad view cannot hide itself by inflating the spread.

View rule: a view is an outlier when its RMS exceeds
    median + VIEW_K * 1.4826 * MAD   (1.4826 * MAD estimates sigma for normal data)
AND exceeds VIEW_MIN_RATIO * median AND VIEW_MIN_PX. The last two keep a very consistent set (tiny
MAD, e.g. synthetic data) from flagging views that are statistically distinct but practically fine:
on clean renders a view's RMS legitimately reaches 1.6-1.7x the median (steep tilt, more blur), so the
ratio is 2 (it was 1.5, which flagged 0.2-0.5 % of clean views; benchmarks/bench_outliers.py), and a
view under 0.2 px RMS is never implausible for a sub-pixel detector.

Corner rule: the residual length of a corner is Rayleigh-distributed for isotropic Gaussian noise,
whose median is 1.1774 * sigma, so sigma_robust = median(|r|) / 1.1774 over all corners of the
solve. A corner is an outlier when |r| > CORNER_ABS_PX (5 px, never plausible for a sub-pixel
detector) or |r| > max(CORNER_K * sigma_robust, CORNER_MIN_PX). P(|r| > 5 sigma) = exp(-12.5) =
3.7e-6 per corner for clean data.

Corners the rule flags are removed from the solve by default (``solve_rejecting_corners``), as mrcal
does: solve, remove, solve again until no corner is flagged (at most ``MAX_REJECTION_ROUNDS``). Each
round removes only the worst flagged corner of each view: one 8 px corner drags its view's pose, and its
neighbours' residuals with it, past the threshold; they come back under once it is gone. A corner
is kept (still flagged) only when removing it would leave its view with fewer than
``MIN_CORNERS_PER_VIEW`` corners; views themselves are only dropped on request (``--drop-outliers``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.solve import (
    MIN_CORNERS_PER_VIEW,
    IntrinsicsSolution,
    get_model,
    project_points,
    solve_intrinsics,
)
from calibctl.errors import NumericalError

VIEW_K = 3.0
VIEW_MIN_RATIO = 2.0
VIEW_MIN_PX = 0.2
CORNER_K = 5.0
CORNER_MIN_PX = 1.0
CORNER_ABS_PX = 5.0
_MAD_TO_SIGMA = 1.4826
_RAYLEIGH_MEDIAN = float(np.sqrt(2.0 * np.log(2.0)))  # 1.1774


@dataclass(frozen=True)
class CornerOutlier:
    """One corner whose residual is implausible. residual_px = observed - projected."""

    view_index: int
    corner_id: int
    residual_px: float
    dx_px: float
    dy_px: float


@dataclass(frozen=True)
class OutlierReport:
    """Outlier views and corners of one solve.

    Attributes:
        view_threshold_px: per-view RMS above which a view is flagged.
        outlier_views: indices into the solve's views, ascending.
        corner_threshold_px: residual length above which a corner is flagged.
        corner_sigma_robust_px: the robust per-coordinate corner noise estimate.
        outlier_corners: flagged corners, largest residual first.
    """

    view_threshold_px: float
    outlier_views: tuple[int, ...]
    corner_threshold_px: float
    corner_sigma_robust_px: float
    outlier_corners: tuple[CornerOutlier, ...]


def view_outlier_threshold_px(per_view_rms_px: np.ndarray) -> float:
    """The per-view RMS (px) above which a view is an outlier. per_view_rms_px: (V,) float64."""
    rms = np.asarray(per_view_rms_px, dtype=np.float64).ravel()
    median = float(np.median(rms))
    mad = float(np.median(np.abs(rms - median)))
    return max(median + VIEW_K * _MAD_TO_SIGMA * mad, VIEW_MIN_RATIO * median, VIEW_MIN_PX)


def corner_outlier_threshold_px(residuals_px_per_view: Sequence[np.ndarray]) -> tuple[float, float]:
    """(threshold_px, sigma_robust_px) of the corner rule from V arrays (N_i, 2) float64 residuals."""
    lengths = np.concatenate(
        [np.linalg.norm(np.asarray(r).reshape(-1, 2), axis=1) for r in residuals_px_per_view]
    )
    sigma_robust = float(np.median(lengths)) / _RAYLEIGH_MEDIAN
    return min(CORNER_ABS_PX, max(CORNER_K * sigma_robust, CORNER_MIN_PX)), sigma_robust


def view_corner_thresholds_px(
    residuals_px_per_view: Sequence[np.ndarray], session_threshold_px: float
) -> np.ndarray:
    """(V,) the corner threshold per view: the session's, raised to CORNER_K x the view's own robust sigma
    (capped at CORNER_ABS_PX). A view that is noisy throughout is a view problem (the view rule's), not
    a set of bad corners: at 5x the session's noise, most of its corners pass the session threshold."""
    own = np.array(
        [
            np.median(np.linalg.norm(np.asarray(r).reshape(-1, 2), axis=1)) / _RAYLEIGH_MEDIAN
            if len(r)
            else 0.0
            for r in residuals_px_per_view
        ]
    )
    return np.minimum(
        np.maximum(CORNER_K * own, session_threshold_px), max(CORNER_ABS_PX, session_threshold_px)
    )


def find_corner_outliers(
    residuals_px_per_view: Sequence[np.ndarray],
    threshold_px: float | Sequence[float] | np.ndarray,
    corner_ids_per_view: Sequence[np.ndarray] | None = None,
    view_indices: Sequence[int] | None = None,
) -> tuple[CornerOutlier, ...]:
    """Corners whose residual length exceeds ``threshold_px``, largest first.

    Args:
        residuals_px_per_view: V arrays (N_i, 2) float64, observed - projected, px.
        threshold_px: from corner_outlier_threshold_px (of the fit, when checking held-out views), or
            one per view (view_corner_thresholds_px).
        corner_ids_per_view: V arrays (N_i,) int64 board corner ids; default the row position.
        view_indices: the view index to report for each entry; default 0..V-1.
    """
    found = []
    limits = np.broadcast_to(np.asarray(threshold_px, dtype=np.float64), (len(residuals_px_per_view),))
    for k, res in enumerate(residuals_px_per_view):
        res = np.asarray(res, dtype=np.float64).reshape(-1, 2)
        ids = (
            np.arange(len(res))
            if corner_ids_per_view is None
            else np.asarray(corner_ids_per_view[k], dtype=np.int64).ravel()
        )
        view = k if view_indices is None else int(view_indices[k])
        norm = np.linalg.norm(res, axis=1)
        for j in np.flatnonzero(norm > limits[k]):
            found.append(CornerOutlier(view, int(ids[j]), float(norm[j]), float(res[j, 0]), float(res[j, 1])))
    found.sort(key=lambda c: (-c.residual_px, c.view_index, c.corner_id))
    return tuple(found)


def flag_outliers(
    solution: IntrinsicsSolution,
    corner_ids_per_view: Sequence[np.ndarray] | None = None,
) -> OutlierReport:
    """Flag outlier views and corners of ``solution``.

    Args:
        solution: a solve.
        corner_ids_per_view: optional V arrays (N_i,) int64 board corner ids (row-major); when
            omitted the position of the corner in its view is reported as its id.
    """
    threshold_view = view_outlier_threshold_px(solution.per_view_rms_px)
    views = tuple(int(i) for i in np.flatnonzero(solution.per_view_rms_px > threshold_view))
    threshold_corner, sigma_robust = corner_outlier_threshold_px(solution.residuals_px)
    per_view = view_corner_thresholds_px(solution.residuals_px, threshold_corner)
    corners = find_corner_outliers(solution.residuals_px, per_view, corner_ids_per_view)
    return OutlierReport(threshold_view, views, threshold_corner, sigma_robust, corners)


@dataclass(frozen=True)
class DropOutliersResult:
    """A re-solve without the outlier views of a first solve.

    Attributes:
        solution: the re-solve on the kept views (its arrays are indexed by kept view).
        first: the solve on all views, whose outliers were dropped.
        dropped_views: indices into the ORIGINAL views that were dropped, ascending.
        kept_views: indices into the original views the re-solve used, ascending.
    """

    solution: IntrinsicsSolution
    first: IntrinsicsSolution
    dropped_views: tuple[int, ...]
    kept_views: tuple[int, ...]


def solve_dropping_outliers(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: str = DEFAULT_MODEL,
    initial: np.ndarray | None = None,
) -> DropOutliersResult:
    """Solve, drop the outlier views (one pass, not iterated), solve again on the rest.

    Shapes as in solve_intrinsics. One pass keeps the result predictable: iterating the rule on a
    shrinking set tightens the threshold every round and can eat good views.

    Raises:
        NumericalError: dropping the outliers leaves fewer views than the model needs.
    """
    first = solve_intrinsics(object_points_per_view, image_points_per_view, image_size, model, initial)
    dropped = flag_outliers(first).outlier_views
    kept = tuple(i for i in range(first.n_views) if i not in dropped)
    if not dropped:
        return DropOutliersResult(first, first, (), kept)
    m = get_model(model)
    if len(kept) < m.min_views:
        raise NumericalError(
            f"dropping {len(dropped)} outlier views leaves {len(kept)}, fewer than the "
            f"{m.min_views} model {m.name} needs",
            hint="capture more views, or solve without --drop-outliers",
        )
    second = solve_intrinsics(
        [object_points_per_view[i] for i in kept],
        [image_points_per_view[i] for i in kept],
        image_size,
        model,
        initial,
    )
    return DropOutliersResult(second, first, dropped, kept)


MAX_REJECTION_ROUNDS = 10


@dataclass(frozen=True)
class CornerRejection:
    """A solve with the implausible corners removed.

    Attributes:
        solution: the solve on the kept corners (its residuals are of the kept corners only).
        keep_masks: V arrays (N_i,) bool over each view's ORIGINAL corners: True = used in the solve.
        rejected: the removed corners, residual against ``solution`` (intrinsics and the view's pose),
            largest first; view_index and corner_id refer to the original views and board ids.
        threshold_px: the corner rule's threshold in the last round.
        rounds: solves run (1 = nothing was rejected).
    """

    solution: IntrinsicsSolution
    keep_masks: tuple[np.ndarray, ...]
    rejected: tuple[CornerOutlier, ...]
    threshold_px: float
    rounds: int

    def kept(self, per_view: Sequence[np.ndarray]) -> list[np.ndarray]:
        """``per_view`` (V arrays with one row per original corner) restricted to the kept corners."""
        return [np.asarray(a)[m] for a, m in zip(per_view, self.keep_masks, strict=True)]


def solve_rejecting_corners(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: str = DEFAULT_MODEL,
    corner_ids_per_view: Sequence[np.ndarray] | None = None,
) -> CornerRejection:
    """Solve, remove the corners the corner rule flags, solve again until none is flagged.

    Shapes as in solve_intrinsics; corner_ids_per_view as in find_corner_outliers.
    """
    masks = [np.ones(len(np.asarray(p).reshape(-1, 2)), dtype=bool) for p in image_points_per_view]
    ids = [
        np.arange(len(m)) if corner_ids_per_view is None else np.asarray(corner_ids_per_view[k]).ravel()
        for k, m in enumerate(masks)
    ]
    rounds = 0
    while True:
        rounds += 1
        obj = [np.asarray(o).reshape(-1, 3)[m] for o, m in zip(object_points_per_view, masks, strict=True)]
        img = [np.asarray(p).reshape(-1, 2)[m] for p, m in zip(image_points_per_view, masks, strict=True)]
        solution = solve_intrinsics(obj, img, image_size, model)
        threshold, _ = corner_outlier_threshold_px(solution.residuals_px)
        flagged = find_corner_outliers(
            solution.residuals_px,
            view_corner_thresholds_px(solution.residuals_px, threshold),
            [i[m] for i, m in zip(ids, masks, strict=True)],
        )
        removed = 0
        done_views: set[int] = set()
        for c in flagged:  # largest first: only each view's worst goes, as it drags its neighbours
            mask = masks[c.view_index]
            if (
                rounds > MAX_REJECTION_ROUNDS
                or mask.sum() <= MIN_CORNERS_PER_VIEW
                or c.view_index in done_views
            ):
                continue
            mask[np.flatnonzero(ids[c.view_index] == c.corner_id)] = False
            done_views.add(c.view_index)
            removed += 1
        if removed == 0:
            break
    return CornerRejection(
        solution,
        tuple(masks),
        _rejected_residuals(object_points_per_view, image_points_per_view, ids, masks, solution),
        threshold,
        rounds,
    )


def _rejected_residuals(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    ids: Sequence[np.ndarray],
    masks: Sequence[np.ndarray],
    solution: IntrinsicsSolution,
) -> tuple[CornerOutlier, ...]:
    """Residual (observed - projected) of every removed corner under the final solve."""
    out = []
    for k, mask in enumerate(masks):
        if mask.all():
            continue
        obj = np.asarray(object_points_per_view[k], np.float64).reshape(-1, 3)[~mask]
        img = np.asarray(image_points_per_view[k], np.float64).reshape(-1, 2)[~mask]
        proj = project_points(
            obj,
            solution.rvecs[k],
            solution.tvecs[k],
            solution.camera_matrix,
            solution.dist_coeffs,
            solution.model,
        )
        res = img - proj
        out += [
            CornerOutlier(k, int(i), float(np.hypot(*r)), float(r[0]), float(r[1]))
            for i, r in zip(ids[k][~mask], res, strict=True)
        ]
    out.sort(key=lambda c: (-c.residual_px, c.view_index, c.corner_id))
    return tuple(out)
