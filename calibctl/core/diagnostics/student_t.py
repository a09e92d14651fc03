"""Student's t distribution without scipy: CDF, two-sided p-value and quantile.

The CDF uses the regularised incomplete beta function,

    P(|T| > t) = I_x(dof/2, 1/2)   with   x = dof / (dof + t^2),

evaluated by the modified Lentz continued fraction (Numerical Recipes, 3rd ed., section 6.4). The
quantile inverts the CDF by bracketed bisection, so it is exact to the CDF's precision (about 1e-12)
for every dof, including the small ones (dof = 1..10) where a normal approximation would be badly
wrong. ``dof = inf`` uses the normal distribution (``math.erfc``). All functions take and return
plain floats; callers vectorise if they need to.
"""

from __future__ import annotations

import math

_CF_MAX_ITER = 400
_CF_EPS = 1e-15
_CF_TINY = 1e-300


def _beta_continued_fraction(a: float, b: float, x: float) -> float:
    """Continued fraction for I_x(a, b) (modified Lentz); converges fast for x < (a+1)/(a+b+2)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > _CF_TINY else _CF_TINY)
    h = d
    for m in range(1, _CF_MAX_ITER + 1):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > _CF_TINY else _CF_TINY)
        c = 1.0 + aa / c
        c = c if abs(c) > _CF_TINY else _CF_TINY
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > _CF_TINY else _CF_TINY)
        c = 1.0 + aa / c
        c = c if abs(c) > _CF_TINY else _CF_TINY
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < _CF_EPS:
            return h
    raise ArithmeticError(f"incomplete beta continued fraction did not converge (a={a}, b={b}, x={x})")


def regularized_incomplete_beta(a: float, b: float, x: float) -> float:
    """I_x(a, b) for a, b > 0 and 0 <= x <= 1."""
    if not (a > 0 and b > 0):
        raise ValueError("a and b must be positive")
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    front = math.exp(log_front)
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _beta_continued_fraction(a, b, x) / a
    return 1.0 - front * _beta_continued_fraction(b, a, 1.0 - x) / b


def t_sf_two_sided(t: float, dof: float) -> float:
    """P(|T| >= |t|) for Student's t with ``dof`` degrees of freedom (the two-sided p-value)."""
    if dof <= 0:
        raise ValueError("dof must be positive")
    if math.isnan(t):
        return math.nan
    if math.isinf(t):
        return 0.0
    if math.isinf(dof):
        return math.erfc(abs(t) / math.sqrt(2.0))
    return regularized_incomplete_beta(dof / 2.0, 0.5, dof / (dof + t * t))


def t_cdf(t: float, dof: float) -> float:
    """P(T <= t) for Student's t with ``dof`` degrees of freedom."""
    tail = 0.5 * t_sf_two_sided(t, dof)
    return 1.0 - tail if t > 0 else tail


def t_quantile(p: float, dof: float) -> float:
    """The t with P(T <= t) = p (0 < p < 1), by bisection on :func:`t_cdf`."""
    if not 0.0 < p < 1.0:
        raise ValueError("p must be in (0, 1)")
    if p == 0.5:
        return 0.0
    if p < 0.5:
        return -t_quantile(1.0 - p, dof)
    hi = 1.0
    while t_cdf(hi, dof) < p:  # the Cauchy (dof=1) 0.9995 quantile is ~637, so this ends quickly
        hi *= 2.0
        if hi > 1e12:
            raise ArithmeticError("t quantile out of range")
    lo = 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if t_cdf(mid, dof) < p:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * max(1.0, hi):
            break
    return 0.5 * (lo + hi)


def t_critical(level: float, dof: float) -> float:
    """Half-width multiplier of a two-sided ``level`` interval (0.95 -> 2.776 at dof 4, 1.960 at inf)."""
    if not 0.0 < level < 1.0:
        raise ValueError("level must be in (0, 1)")
    return t_quantile(0.5 + level / 2.0, dof)
