"""Ordinary least squares with honest standard errors, group aggregation and collinearity checks.

Everything here is the arithmetic of the seed's chapter 4 ("fitting the covariate, by hand"):

- ``fit_ols``: y = X beta + e. Standard errors come from the residual variance
  s^2 = RSS / (n - p) with the right degrees of freedom, Cov(beta) = s^2 (X^T X)^-1, t = beta / SE,
  and two-sided intervals use the Student t quantile of :mod:`student_t`.
- ``aggregate_by_group``: one mean per keyframe before fitting, so that residuals that share a pose
  (and therefore share an error) count once, not two hundred times.
- ``column_correlations`` / ``variance_inflation``: the collinearity guard; a fit whose columns are
  near-copies of each other must not attribute the effect to one of them.

Columns are rescaled to unit RMS before solving, so r^3 (~1e8 px^3) and 1/Z (~0.1 1/m) can share a
design matrix without destroying the normal equations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibctl.core.diagnostics.student_t import t_critical, t_sf_two_sided
from calibctl.errors import NumericalError


@dataclass(frozen=True)
class LinearFit:
    """Result of one OLS fit. Arrays are (p,) in the order of ``names``; units are the callers'."""

    names: tuple[str, ...]
    coef: np.ndarray
    se: np.ndarray
    t: np.ndarray
    p_value: np.ndarray
    cov: np.ndarray
    dof: int
    n: int
    rss: float
    sigma: float

    def interval(self, level: float = 0.95) -> np.ndarray:
        """(p, 2) two-sided ``level`` intervals, coef -/+ t_{dof} * SE."""
        half = t_critical(level, self.dof) * self.se
        return np.stack([self.coef - half, self.coef + half], axis=1)

    def index(self, name: str) -> int:
        return self.names.index(name)


def fit_ols(X: np.ndarray, y: np.ndarray, names: tuple[str, ...] | list[str]) -> LinearFit:
    """Least-squares fit of y on the columns of X (include a column of ones for an intercept).

    X: (n, p) float64, y: (n,) float64. Raises NumericalError when n <= p (no degrees of freedom
    for the noise) or when X is rank-deficient (a column is a combination of the others).
    """
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if X.ndim != 2 or y.ndim != 1 or X.shape[0] != y.shape[0]:
        raise ValueError(f"shapes do not match: X {X.shape}, y {y.shape}")
    n, p = X.shape
    if len(names) != p:
        raise ValueError("one name per column")
    if n <= p:
        raise NumericalError(
            f"{n} data points cannot fit {p} parameters and still estimate the noise",
            hint="collect more keyframes",
        )
    scale = np.sqrt(np.mean(X * X, axis=0))
    if np.any(scale == 0):
        zero = [names[i] for i in np.flatnonzero(scale == 0)]
        raise NumericalError(f"column(s) {', '.join(zero)} are identically zero: nothing to fit")
    Xs = X / scale
    U, sv, Vt = np.linalg.svd(Xs, full_matrices=False)
    if sv[-1] <= 1e-10 * sv[0]:
        raise NumericalError(
            f"design matrix is rank-deficient (condition number {sv[0] / max(sv[-1], 1e-300):.3g})",
            hint="two covariates carry the same information in this data",
        )
    beta_s = Vt.T @ ((U.T @ y) / sv)
    resid = y - Xs @ beta_s
    rss = float(resid @ resid)
    dof = n - p
    s2 = rss / dof
    inv_s = (Vt.T / sv**2) @ Vt  # (Xs^T Xs)^-1
    cov = s2 * inv_s / np.outer(scale, scale)
    coef = beta_s / scale
    se = np.sqrt(np.diag(cov))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(se > 0, coef / np.where(se > 0, se, 1.0), np.copysign(np.inf, coef))
    t = np.where((se == 0) & (coef == 0), 0.0, t)
    p_value = np.array([t_sf_two_sided(float(ti), dof) for ti in t])
    return LinearFit(tuple(names), coef, se, t, p_value, cov, dof, n, rss, math.sqrt(s2))


def fit_line(x: np.ndarray, y: np.ndarray, intercept: bool = True) -> LinearFit:
    """y = a + b x (names "intercept", "slope"), or y = b x through the origin (name "slope")."""
    x = np.asarray(x, dtype=np.float64)
    if intercept:
        return fit_ols(np.column_stack([np.ones_like(x), x]), y, ("intercept", "slope"))
    return fit_ols(x[:, None], y, ("slope",))


def aggregate_by_group(
    group: np.ndarray, columns: dict[str, np.ndarray]
) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """Mean of each column within each group.

    group: (n,) labels (any dtype). Returns (labels (g,), {name: (g,) means}, counts (g,) int).
    Groups come out in sorted label order.
    """
    labels, inverse = np.unique(np.asarray(group), return_inverse=True)
    counts = np.bincount(inverse, minlength=labels.size)
    means = {
        name: np.bincount(inverse, weights=np.asarray(col, dtype=np.float64), minlength=labels.size) / counts
        for name, col in columns.items()
    }
    return labels, means, counts


def column_correlations(X: np.ndarray) -> np.ndarray:
    """(p, p) Pearson correlations of the columns of X (n, p). Constant columns get NaN rows."""
    X = np.asarray(X, dtype=np.float64)
    Xc = X - X.mean(axis=0)
    norm = np.sqrt(np.sum(Xc * Xc, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        Z = Xc / norm
        corr = Z.T @ Z
    corr[:, norm == 0] = np.nan
    corr[norm == 0, :] = np.nan
    return corr


def variance_inflation(X: np.ndarray) -> np.ndarray:
    """(p,) variance inflation factors of the (non-constant) columns of X: diag(inv(corr)).

    VIF = 1 / (1 - R^2 of that column on the others); 1 means orthogonal, 32 is the seed's
    r^3-vs-r^5 example (still decisive), ~1000 means the column is a near-copy of the others.
    Returns inf where the correlation matrix is singular.
    """
    corr = column_correlations(X)
    if np.any(~np.isfinite(corr)):
        raise ValueError("constant column: drop it before computing VIFs")
    sv = np.linalg.svd(corr, compute_uv=False)
    if sv[-1] <= 1e-13 * sv[0]:
        return np.full(corr.shape[0], np.inf)
    return np.diag(np.linalg.inv(corr)).copy()


def fit_radial_orders(
    radius_px: np.ndarray, residual_px: np.ndarray, radius_max_px: float | None = None
) -> tuple[LinearFit, float]:
    """Through-origin fit residual = b3 rho^3 + b5 rho^5 with rho = r / r_max (seed chapter 4).

    No intercept: radial distortion is zero at the principal point. The coefficients are pixels of
    offset at r_max, so k1 = b3 f^2 / r_max^3. Returns (fit with names ("r3", "r5"), corr(rho^3, rho^5)).
    """
    r = np.asarray(radius_px, dtype=np.float64)
    r_max = float(np.max(r)) if radius_max_px is None else float(radius_max_px)
    rho = r / r_max
    c3, c5 = rho**3, rho**5
    corr = float(c3 @ c5 / math.sqrt(float(c3 @ c3) * float(c5 @ c5)))  # uncentred: no intercept
    return fit_ols(np.column_stack([c3, c5]), residual_px, ("r3", "r5")), corr
