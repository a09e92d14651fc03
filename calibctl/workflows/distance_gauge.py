"""The gauge at the station: a board held by a fixture at a surveyed distance (seed chapter 0).

A wrong board scale s leaves K, the distortion and every residual exactly as they were and multiplies
every recovered translation by s. Only an independent metric distance can see it, so the recovered
camera-to-board-centre distance is compared with a surveyed one: a ratio outside 0.99-1.01 fails.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from calibctl.artifacts.check import DistanceCheck
from calibctl.core.recheck import distance_ratio
from calibctl.errors import InputError, UsageError

RATIO_LIMITS = (0.99, 1.01)
MAX_RELATIVE_SIGMA = 0.003  # a survey looser than this cannot judge a 1 % scale error
MAX_SPREAD = 0.02  # views farther apart than this were not all in the fixture
_TEXT = re.compile(r"^\s*(?P<d>[0-9]*\.?[0-9]+)\s*(?:\+-|\+/-|±)\s*(?P<s>[0-9]*\.?[0-9]+)\s*(?P<unit>m|mm)?\s*$")
_UNIT_FACTORS = {10.0: "a factor of 10 (cm for m?)", 100.0: "a factor of 100 (cm?)", 1000.0: "a factor of 1000 (mm for m?)"}


@dataclass(frozen=True)
class ReferenceDistance:
    distance_m: float
    sigma_m: float


def parse_reference_distance(text: str) -> ReferenceDistance:
    """``D+-S`` in metres (or with an ``mm`` suffix), e.g. ``0.600+-0.001`` or ``600+-1mm``."""
    match = _TEXT.match(text)
    if not match:
        raise UsageError(f"--reference-distance '{text}' is not D+-S",
                         "the surveyed camera-to-board-centre distance and its one-sigma, e.g. 0.600+-0.001 (metres)")
    scale = 0.001 if match.group("unit") == "mm" else 1.0
    d, s = float(match.group("d")) * scale, float(match.group("s")) * scale
    if d <= 0:
        raise UsageError(f"--reference-distance must be positive, got {text}")
    if s / d > MAX_RELATIVE_SIGMA:
        raise UsageError(f"--reference-distance {text}: a one-sigma of {100 * s / d:.2f} % cannot judge a 1 % scale "
                         "error", f"survey the fixture to {100 * MAX_RELATIVE_SIGMA:.1f} % or better")
    return ReferenceDistance(d, s)


def judge_distance(ref: ReferenceDistance, recovered_m: np.ndarray, names: list[str]) -> DistanceCheck:
    """Compare the per-view recovered distances with the surveyed one (InputError when it cannot be judged)."""
    ratio, spread = distance_ratio(recovered_m, ref.distance_m)
    if spread > MAX_SPREAD:
        near, far = int(np.argmin(recovered_m)), int(np.argmax(recovered_m))
        raise InputError(
            f"the board was not held at one distance: {names[near]} at {recovered_m[near]:.3f} m, {names[far]} at "
            f"{recovered_m[far]:.3f} m; a reference distance of {ref.distance_m:.3f} m cannot be matched by all views",
            "check with only the pictures taken with the board in the fixture")
    for factor, what in _UNIT_FACTORS.items():
        for guess in (factor, 1.0 / factor):
            if abs(ratio / guess - 1.0) < 0.25:
                raise InputError(
                    f"the board is {float(np.median(recovered_m)):.3f} m away but --reference-distance says "
                    f"{ref.distance_m:g} m: off by {what}, not a scale error",
                    "give the distance in metres, e.g. 0.600+-0.001, or with an mm suffix: 600+-1mm")
    if not 0.5 < ratio < 2.0:
        raise InputError(
            f"the board is {float(np.median(recovered_m)):.3f} m away, nowhere near the surveyed {ref.distance_m:.3f} m "
            f"(ratio {ratio:.2f})", "put the board in the fixture, or check the surveyed distance and its units")
    lo, hi = RATIO_LIMITS
    return DistanceCheck(reference_m=ref.distance_m, reference_sigma_m=ref.sigma_m,
                         recovered_m=float(np.median(recovered_m)), spread=spread, ratio=ratio,
                         ratio_limits=RATIO_LIMITS, passed=lo <= ratio <= hi)
