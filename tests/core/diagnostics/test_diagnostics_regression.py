"""Student t and OLS: the seed's chapter 4 worked numbers, table values, and interval coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibctl.core.diagnostics.regression import (
    aggregate_by_group,
    column_correlations,
    fit_line,
    fit_ols,
    fit_radial_orders,
    variance_inflation,
)
from calibctl.core.diagnostics.student_t import (
    regularized_incomplete_beta,
    t_cdf,
    t_critical,
    t_quantile,
    t_sf_two_sided,
)
from calibctl.errors import NumericalError

# Two-sided 95% critical values from printed t tables (e.g. NIST/SEMATECH e-Handbook 1.3.6.7.2).
T_TABLE_975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 10: 2.228, 30: 2.042, 120: 1.980}


@pytest.mark.parametrize(("dof", "expected"), sorted(T_TABLE_975.items()))
def test_t_critical_matches_printed_tables(dof, expected):
    assert t_critical(0.95, dof) == pytest.approx(expected, abs=6e-4)


def test_t_quantile_tails_and_normal_limit():
    assert t_quantile(0.9995, 6) == pytest.approx(5.959, abs=1e-3)  # the naming threshold's table value
    assert t_quantile(0.995, 1) == pytest.approx(63.657, abs=1e-3)
    assert t_critical(0.95, math.inf) == pytest.approx(1.959964, abs=1e-6)
    assert t_quantile(0.025, 4) == pytest.approx(-t_quantile(0.975, 4), abs=1e-12)


def test_incomplete_beta_closed_forms():
    for x in (0.1, 0.37, 0.9):
        assert regularized_incomplete_beta(1.0, 1.0, x) == pytest.approx(x, abs=1e-13)
        assert regularized_incomplete_beta(3.0, 1.0, x) == pytest.approx(x**3, abs=1e-13)
    assert regularized_incomplete_beta(7.5, 7.5, 0.5) == pytest.approx(0.5, abs=1e-13)


def test_t_with_one_dof_is_cauchy():
    for t in (-3.0, -0.4, 0.0, 1.0, 25.0):
        assert t_cdf(t, 1) == pytest.approx(0.5 + math.atan(t) / math.pi, abs=1e-12)
    assert t_sf_two_sided(2.0, 10) == pytest.approx(0.073388, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(p=st.floats(0.001, 0.999), dof=st.integers(1, 400))
def test_quantile_inverts_cdf(p, dof):
    assert t_cdf(t_quantile(p, dof), dof) == pytest.approx(p, abs=1e-9)


def test_seed_chapter4_binned_means_give_18475_ms_at_t_339():
    speed_px_s = np.array([0.0, 200.0, 400.0, 600.0, 800.0])
    mean_residual_px = np.array([0.05, 3.75, 7.30, 11.10, 14.80])
    fit = fit_line(speed_px_s, mean_residual_px, intercept=False)
    assert fit.coef[0] == pytest.approx(0.0184750, abs=1e-10)  # 18.475 ms
    assert fit.dof == 4
    assert fit.sigma == pytest.approx(0.05969, abs=1e-5)
    assert fit.se[0] == pytest.approx(5.449e-5, abs=1e-8)
    assert fit.t[0] == pytest.approx(339.1, abs=0.05)


def test_seed_chapter4_r3_r5_fit():
    r = np.array([100.0, 200.0, 300.0, 400.0, 460.0])
    y = np.array([0.0229, 0.1738, 0.5920, 1.3991, 2.1298])
    fit, corr = fit_radial_orders(r, y)
    b3, b5 = fit.coef
    assert b3 == pytest.approx(2.128880, abs=2e-6)
    assert b5 == pytest.approx(0.000588, abs=2e-6)
    assert fit.se == pytest.approx([0.006169, 0.006764], abs=2e-6)
    assert fit.t[0] == pytest.approx(345.1, abs=0.1)
    assert abs(fit.t[1]) < 0.1  # indistinguishable from zero
    assert fit.dof == 3
    assert corr == pytest.approx(0.9841, abs=1e-4)
    assert b3 * 800.0**2 / 460.0**3 == pytest.approx(0.013998, abs=1e-6)  # back to dk1


def test_seed_chapter5_bench_columns_and_joint_fit():
    """Six structures; the joint fit puts each noise-free fault in exactly one column (seed chapter 5)."""
    z = np.array([1.0, 2.0, 5.0, 10.0, 20.0, 50.0])
    r = np.array([80.0, 160.0, 240.0, 320.0, 400.0, 460.0])
    u = 800.0 * np.array([0.300, 0.575, 0.275, 0.225, 0.575, 0.300])
    assert float((u - u.mean()) @ (r - r.mean())) == pytest.approx(-400.0, abs=1e-9)
    assert column_correlations(np.column_stack([u, r]))[0, 1] == pytest.approx(-0.0044, abs=5e-5)
    X = np.column_stack([np.ones(6), r, r**3, 1.0 / z, u])
    names = ("1", "r", "r3", "1/Z", "u")
    cases = {
        "focal": (0.02 * r, {"r": 0.02}),
        "k1": (0.02 * r**3 / 800.0**2, {"r3": 3.125e-8}),
        "translation": (800.0 * 0.02 / z, {"1/Z": 16.0}),
        "time-offset": (0.0184 * u, {"u": 0.0184}),
        "rotation": (np.full(6, 800.0 * math.tan(math.radians(1.0))), {"1": 13.964}),
        "principal-point": (np.full(6, 10.0), {"1": 10.0}),
    }
    for residual, expected in cases.values():
        coef = fit_ols(X, residual, names).coef
        for i, name in enumerate(names):
            want = expected.get(name, 0.0)
            assert coef[i] == pytest.approx(want, rel=1e-3, abs=1e-9 if want == 0 else 0.0)
    # the marginal velocity slope of experiment 4 reads 18.40 ms from the six means
    assert fit_line(u, 0.0184 * u).coef[1] == pytest.approx(0.0184, abs=1e-12)


def test_interval_coverage_is_nominal_at_small_dof():
    """95% t intervals on dof = 4 cover ~95%; a normal 1.96 interval would cover only ~88%."""
    rng = np.random.default_rng(11)
    x = np.linspace(0.0, 1.0, 6)
    covered, covered_normal, n_rep = 0, 0, 2000
    for _ in range(n_rep):
        fit = fit_line(x, 1.0 + 2.0 * x + rng.normal(0.0, 0.5, x.size))
        lo, hi = fit.interval(0.95)[1]
        covered += lo <= 2.0 <= hi
        covered_normal += abs(fit.coef[1] - 2.0) <= 1.96 * fit.se[1]
    assert 0.93 <= covered / n_rep <= 0.97  # +/- 3 binomial standard errors
    assert covered_normal / n_rep < 0.91


def test_standard_error_matches_scatter_of_the_slope():
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 10.0, 40)
    slopes, ses = [], []
    for _ in range(1500):
        fit = fit_line(x, 3.0 - 0.7 * x + rng.normal(0.0, 2.0, x.size))
        slopes.append(fit.coef[1])
        ses.append(fit.se[1])
    assert np.std(slopes) == pytest.approx(np.sqrt(np.mean(np.square(ses))), rel=0.06)


def test_refuses_rank_deficient_and_dofless_fits():
    x = np.arange(10.0)
    with pytest.raises(NumericalError, match="rank-deficient"):
        fit_ols(np.column_stack([np.ones(10), x, 2.0 * x]), x, ("1", "a", "b"))
    with pytest.raises(NumericalError, match="cannot fit 2 parameters"):
        fit_line(np.array([1.0, 2.0]), np.array([1.0, 3.0]))
    with pytest.raises(NumericalError, match="identically zero"):
        fit_ols(np.column_stack([np.ones(10), np.zeros(10)]), x, ("1", "z"))


def test_aggregate_by_group_means_and_counts():
    labels, means, counts = aggregate_by_group(
        np.array(["b", "a", "b", "a", "a"]), {"y": np.array([1.0, 2.0, 3.0, 4.0, 6.0])}
    )
    assert labels.tolist() == ["a", "b"]
    assert counts.tolist() == [3, 2]
    assert means["y"].tolist() == [4.0, 2.0]


def test_variance_inflation_of_two_correlated_columns():
    rng = np.random.default_rng(2)
    a = rng.normal(size=5000)
    b = 0.9 * a + math.sqrt(1 - 0.81) * rng.normal(size=5000)
    rho = column_correlations(np.column_stack([a, b]))[0, 1]
    vif = variance_inflation(np.column_stack([a, b]))
    assert vif == pytest.approx([1 / (1 - rho**2)] * 2, rel=1e-9)
    assert np.all(np.isinf(variance_inflation(np.column_stack([a, 2 * a]))))
