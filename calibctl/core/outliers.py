"""Outlier views and outlier corners of a solve, and the re-solve without the outlier views.

Both rules are robust (median and MAD), so one bad view cannot hide itself by inflating the spread.

View rule: a view is an outlier when its RMS exceeds
    median + VIEW_K * 1.4826 * MAD   (1.4826 * MAD estimates sigma for normal data)
AND exceeds VIEW_MIN_RATIO * median. The second clause keeps a very consistent set (tiny MAD, e.g.
synthetic data) from flagging views that are statistically distinct but practically fine.

Corner rule: the residual length of a corner is Rayleigh-distributed for isotropic Gaussian noise,
whose median is 1.1774 * sigma, so sigma_robust = median(|r|) / 1.1774 over all corners of the
solve. A corner is an outlier when |r| > CORNER_ABS_PX (5 px, never plausible for a sub-pixel
detector) or |r| > max(CORNER_K * sigma_robust, CORNER_MIN_PX). P(|r| > 5 sigma) = exp(-12.5) =
3.7e-6 per corner for clean data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.solve import IntrinsicsSolution, get_model, solve_intrinsics
from calibctl.errors import NumericalError

VIEW_K = 3.0
VIEW_MIN_RATIO = 1.5
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
    return max(median + VIEW_K * _MAD_TO_SIGMA * mad, VIEW_MIN_RATIO * median)


def corner_outlier_threshold_px(residuals_px_per_view: Sequence[np.ndarray]) -> tuple[float, float]:
    """(threshold_px, sigma_robust_px) of the corner rule from V arrays (N_i, 2) float64 residuals."""
    lengths = np.concatenate([np.linalg.norm(np.asarray(r).reshape(-1, 2), axis=1)
                              for r in residuals_px_per_view])
    sigma_robust = float(np.median(lengths)) / _RAYLEIGH_MEDIAN
    return min(CORNER_ABS_PX, max(CORNER_K * sigma_robust, CORNER_MIN_PX)), sigma_robust


def find_corner_outliers(
    residuals_px_per_view: Sequence[np.ndarray],
    threshold_px: float,
    corner_ids_per_view: Sequence[np.ndarray] | None = None,
    view_indices: Sequence[int] | None = None,
) -> tuple[CornerOutlier, ...]:
    """Corners whose residual length exceeds ``threshold_px``, largest first.

    Args:
        residuals_px_per_view: V arrays (N_i, 2) float64, observed - projected, px.
        threshold_px: from corner_outlier_threshold_px (of the fit, when checking held-out views).
        corner_ids_per_view: V arrays (N_i,) int64 board corner ids; default the row position.
        view_indices: the view index to report for each entry; default 0..V-1.
    """
    found = []
    for k, res in enumerate(residuals_px_per_view):
        res = np.asarray(res, dtype=np.float64).reshape(-1, 2)
        ids = (np.arange(len(res)) if corner_ids_per_view is None
               else np.asarray(corner_ids_per_view[k], dtype=np.int64).ravel())
        view = k if view_indices is None else int(view_indices[k])
        norm = np.linalg.norm(res, axis=1)
        for j in np.flatnonzero(norm > threshold_px):
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
    corners = find_corner_outliers(solution.residuals_px, threshold_corner, corner_ids_per_view)
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
    model: str = "k1k2",
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
            f"{m.min_views} model {m.name} needs", hint="capture more views, or solve without --drop-outliers")
    second = solve_intrinsics([object_points_per_view[i] for i in kept],
                              [image_points_per_view[i] for i in kept], image_size, model, initial)
    return DropOutliersResult(second, first, dropped, kept)
