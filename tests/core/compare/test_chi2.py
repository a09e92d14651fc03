"""The chi-square survival function and quantile against tabulated values."""

from __future__ import annotations

import math

import pytest

from calibctl.core.compare.chi2 import chi2_quantile, chi2_sf


@pytest.mark.parametrize(
    ("x", "dof", "p"),
    [
        (3.841459, 1, 0.05),
        (6.634897, 1, 0.01),
        (9.236357, 5, 0.1),
        (16.749602, 5, 0.005),
        (20.090235, 8, 0.01),
        (2.0, 2, math.exp(-1.0)),
        (63.690740, 40, 0.01),
    ],
)
def test_survival_function_matches_the_table(x: float, dof: int, p: float) -> None:
    assert chi2_sf(x, dof) == pytest.approx(p, rel=1e-5)


@pytest.mark.parametrize("dof", [1, 2, 5, 8, 16, 40])
def test_quantile_inverts_the_survival_function(dof: int) -> None:
    for p in (0.5, 0.99, 0.995):
        assert chi2_sf(chi2_quantile(p, dof), dof) == pytest.approx(1.0 - p, rel=1e-8)


def test_bad_arguments_are_refused() -> None:
    assert chi2_sf(0.0, 3) == 1.0
    with pytest.raises(ValueError, match="dof"):
        chi2_sf(1.0, 0)
    with pytest.raises(ValueError, match="p must"):
        chi2_quantile(1.0, 3)
