"""The chi-square distribution without scipy: survival function and quantile.

P(X > x) for X ~ chi2(k) is the regularised upper incomplete gamma Q(k/2, x/2), evaluated by its
series below a + 1 and by the modified Lentz continued fraction above (Numerical Recipes, 3rd ed.,
section 6.2); the quantile inverts it by bisection, so it is exact to the survival function's
precision (about 1e-13) for every dof.
"""

from __future__ import annotations

import math

_MAX_ITER = 500
_EPS = 1e-15
_TINY = 1e-300


def _lower_series(a: float, x: float) -> float:
    """P(a, x) by its power series (converges fast for x < a + 1)."""
    term = total = 1.0 / a
    ap = a
    for _ in range(_MAX_ITER):
        ap += 1.0
        term *= x / ap
        total += term
        if abs(term) < abs(total) * _EPS:
            break
    return total * math.exp(-x + a * math.log(x) - math.lgamma(a))


def _upper_fraction(a: float, x: float) -> float:
    """Q(a, x) by its continued fraction (converges fast for x > a + 1)."""
    b = x + 1.0 - a
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, _MAX_ITER + 1):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = b + an / c
        c = c if abs(c) > _TINY else _TINY
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < _EPS:
            break
    return h * math.exp(-x + a * math.log(x) - math.lgamma(a))


def chi2_sf(x: float, dof: int) -> float:
    """P(X > x) for X ~ chi2(dof), dof >= 1."""
    if dof < 1:
        raise ValueError("dof must be at least 1")
    if not x > 0:
        return 1.0
    a, y = dof / 2.0, x / 2.0
    if y < a + 1.0:
        return max(0.0, 1.0 - _lower_series(a, y))
    return min(1.0, _upper_fraction(a, y))


def chi2_quantile(p: float, dof: int) -> float:
    """The x with P(X <= x) = p for X ~ chi2(dof), 0 < p < 1."""
    if not 0.0 < p < 1.0:
        raise ValueError("p must be in (0, 1)")
    lo, hi = 0.0, float(dof) + 10.0 * math.sqrt(2.0 * dof) + 50.0
    while chi2_sf(hi, dof) > 1.0 - p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if chi2_sf(mid, dof) > 1.0 - p:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * max(1.0, hi):
            break
    return 0.5 * (lo + hi)
