"""The gauge at the desk: does the square size agree with an independent span measurement of the pattern?

Seed chapter 0: a wrong square size (23 mm typed for 25 mm) leaves no residual anywhere; it only shows
against a second, independent measurement of a length. The span is the distance between the outermost
inner corners along the long side, ``squares`` squares long, so the square size implies
``squares * square``. They agree when the difference is within K_SIGMA combined one-sigmas.
A span 10, 100 or 1000 times the implied one (or that fraction) is a unit slip, named as such.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

K_SIGMA = 3.0
UNIT_SLIPS = {10.0: "cm for mm", 100.0: "a factor of 100", 1000.0: "m for mm"}
UNIT_TOLERANCE = 0.2  # within 20 % of a power of ten: a unit slip rather than a bad measurement


@dataclass(frozen=True)
class SpanVerdict:
    """Square size against span, metres. ``unit_factor``: span / implied near 10^k (k != 0), else None."""

    implied_m: float
    span_m: float
    difference_m: float
    combined_sigma_m: float
    unit_factor: float | None

    @property
    def consistent(self) -> bool:
        return self.unit_factor is None and abs(self.difference_m) <= K_SIGMA * self.combined_sigma_m


def compare_span(
    square_m: float, square_sigma_m: float, squares: float, span_m: float, span_sigma_m: float
) -> SpanVerdict:
    """Compare ``squares * square_m`` with ``span_m`` (every length in metres, sigmas one-sigma).

    ``squares`` is how many square edges the span is long; an AprilGrid's span over ``n`` tags is
    ``n + (n - 1) * tag_spacing`` tag edges (the gaps scale with the printed tag)."""
    implied = squares * square_m
    # The square's uncertainty scales with the count when it is one measured square repeated.
    sigma = math.hypot(squares * square_sigma_m, span_sigma_m)
    ratio = span_m / implied
    factor = None
    for slip in UNIT_SLIPS:
        for guess in (slip, 1.0 / slip):
            if abs(ratio / guess - 1.0) < UNIT_TOLERANCE:
                factor = guess
    return SpanVerdict(implied, span_m, span_m - implied, sigma, factor)
