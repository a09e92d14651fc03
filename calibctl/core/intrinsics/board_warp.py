"""Is the board flat? The session re-solved with the board allowed to bow.

A printed board that is not flat (paper on a wall, a print that curls) moves every view's corners off the
plane the solve assumes, by an amount that depends on the view's pose: an error shared by a view's corners,
which the view-level factor (core.intrinsics.covariance) sees and widens the sigma by. A richer lens model
does not remove it, and neither do more views: the fix is a flat board.

The bow is mrcal's board warp: two parabolic cylinders, the corner at normalised board position (x, y) in
[-1, 1] lifted by ``dz = w_x (1 - x^2) + w_y (1 - y^2)`` metres out of the board plane. ``fit_board_warp``
solves (w_x, w_y) beside the lens model by Gauss-Newton on the corners' residuals (each step a re-solve of
the lens from the flat solution's camera matrix, finite differences in w), then the bowed session once with
its uncertainty. The board explains the views' excess scatter when the bowed solve's view-level factor is at
most ``FLAT_FACTOR_DROP`` of the flat one's (phi, the variance ratio, at least halved).

Measured (benchmarks/bench_gate_cause.py, benchmarks/results/verdicts.md): udacity-camcal (a paper board,
mrcal's warp [-0.036, -0.007] squares in its DATASET.md) fits w = [-0.035, -0.006] squares here, RMS 0.879
-> 0.776 px, factor 4.00 -> 1.91, fx 1157.7 -> 1172.7 px (mrcal with warp: 1171.4); on the other real sets
the bow leaves the factor where it was (2.41 -> 2.50, 5.06 -> 5.18, 4.05 -> 4.25, 2.99 -> 2.85).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.intrinsics.solve import IntrinsicsSolution, solve_intrinsics
from calibctl.errors import NumericalError

FLAT_FACTOR_DROP = 0.7  # sqrt(0.5): the bow removes at least half the views' excess variance
GAUSS_NEWTON_STEPS = 6
STEP_FRACTION = 1e-3  # finite-difference step in w, of the board's larger span


@dataclass(frozen=True)
class BoardWarp:
    """The session solved with a bowed board.

    Attributes:
        warp_m: (w_x, w_y) metres, the bow at the board's centre along x and along y.
        flat: the flat solve it started from. bowed: the bowed solve, with its uncertainty.
    """

    warp_m: tuple[float, float]
    flat: IntrinsicsSolution
    bowed: IntrinsicsSolution

    @property
    def factors(self) -> tuple[float, float]:
        """The view-level factor of the flat and of the bowed solve (nan where there is none)."""
        return _factor(self.flat), _factor(self.bowed)

    @property
    def explains_views(self) -> bool:
        """The bow, not the views, is the session's per-view error (module docstring)."""
        before, after = self.factors
        return after <= FLAT_FACTOR_DROP * before  # False when either is nan


def _factor(sol: IntrinsicsSolution) -> float:
    cov = sol.covariance
    return float("nan") if cov is None or cov.view_factor is None else float(cov.view_factor)


def bowed_points(object_points: Sequence[np.ndarray], warp_m: np.ndarray) -> list[np.ndarray]:
    """The board's corners lifted by the bow ``warp_m`` (2,) metres (module docstring), normalised over the
    corners' extent."""
    allp = np.concatenate([np.asarray(o, np.float64) for o in object_points])
    lo, span = allp[:, :2].min(axis=0), np.ptp(allp[:, :2], axis=0)
    span = np.where(span > 0, span, 1.0)
    out = []
    for o in object_points:
        o = np.asarray(o, np.float64)
        xy = 2.0 * (o[:, :2] - lo) / span - 1.0
        dz = warp_m[0] * (1.0 - xy[:, 0] ** 2) + warp_m[1] * (1.0 - xy[:, 1] ** 2)
        out.append(np.column_stack([o[:, :2], o[:, 2] + dz]))
    return out


def fit_board_warp(
    flat: IntrinsicsSolution,
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
) -> BoardWarp | None:
    """The bow that best explains the corners (module docstring), or None when the bowed session cannot be
    solved (a step that diverges ends the search at the last good bow)."""
    img = list(image_points)
    K0 = flat.camera_matrix
    allp = np.concatenate([np.asarray(o, np.float64) for o in object_points])
    h = STEP_FRACTION * float(np.ptp(allp[:, :2], axis=0).max())

    def residuals(w: np.ndarray) -> np.ndarray | None:
        try:
            sol = solve_intrinsics(
                bowed_points(object_points, w), img, flat.image_size, flat.model, K0, False
            )
        except NumericalError:
            return None
        return np.concatenate([r.reshape(-1) for r in sol.residuals_px])

    w = np.zeros(2)
    r = np.concatenate([r.reshape(-1) for r in flat.residuals_px])
    for _ in range(GAUSS_NEWTON_STEPS):
        cols = [residuals(w + h * e) for e in np.eye(2)]
        if any(c is None or c.shape != r.shape for c in cols):
            break
        J = np.column_stack([(c - r) / h for c in cols if c is not None])
        step, *_ = np.linalg.lstsq(J, -r, rcond=None)
        trial = residuals(w + step)
        if trial is None or trial.shape != r.shape or trial @ trial >= r @ r:
            break
        w, r = w + step, trial
    if not w.any():
        return None
    try:
        bowed = solve_intrinsics(bowed_points(object_points, w), img, flat.image_size, flat.model, K0)
    except NumericalError:
        return None
    return BoardWarp((float(w[0]), float(w[1])), flat, bowed)
