"""The shared Levenberg-Marquardt solver: known answers, Schur == dense, and its failure paths."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.lm import Damping, DenseSystem, SchurSystem, damped_step, solve_lm
from calibctl.errors import EXIT_CANNOT_RUN, NumericalError

SCHUR_TOL = 1e-10


def _add(params: np.ndarray, delta: np.ndarray) -> np.ndarray:
    return params + delta


def rosenbrock(x: np.ndarray) -> DenseSystem:
    """Rosenbrock as residuals: observed 0, predicted (10 (x1 - x0^2), 1 - x0); minimum 0 at (1, 1)."""
    predicted = np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])
    J = np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])
    return DenseSystem.from_jacobian(J, -predicted)


def test_rosenbrock_reaches_its_minimum_from_the_classic_start() -> None:
    out = solve_lm(rosenbrock, np.array([-1.2, 1.0]), _add, max_iterations=200)
    assert out.converged and out.stop == "cost"
    np.testing.assert_allclose(out.params, [1.0, 1.0], atol=1e-8)
    assert out.cost < 1e-16
    assert 1 < out.iterations < 200


T_S = np.linspace(0.0, 2.0, 25)


def exponential(params: np.ndarray, observed: np.ndarray = 3.0 * np.exp(-1.3 * T_S) + 0.5) -> DenseSystem:
    """y = a exp(b t) + c; truth (3, -1.3, 0.5)."""
    a, b, c = params
    e = np.exp(b * T_S)
    J = np.column_stack([e, a * T_S * e, np.ones_like(T_S)])
    return DenseSystem.from_jacobian(J, observed - (a * e + c))


def test_exponential_fit_recovers_the_generating_parameters() -> None:
    out = solve_lm(exponential, np.array([1.0, -0.5, 0.0]), _add)
    assert out.converged
    np.testing.assert_allclose(out.params, [3.0, -1.3, 0.5], atol=1e-9)


def test_noisy_exponential_fit_lands_where_the_gradient_vanishes() -> None:
    rng = np.random.default_rng(7)
    observed = 3.0 * np.exp(-1.3 * T_S) + 0.5 + rng.normal(0.0, 0.01, T_S.size)
    out = solve_lm(lambda p: exponential(p, observed), np.array([1.0, -0.5, 0.0]), _add)
    at_min = exponential(out.params, observed)
    assert out.converged
    assert np.max(np.abs(at_min.g)) < 1e-8 * np.max(np.abs(np.diag(at_min.H)))
    np.testing.assert_allclose(out.params, [3.0, -1.3, 0.5], atol=0.1)


# A block problem: shared (a, c), per block v (b_v, d_v): y_v(t) = a exp(b_v t) + c + d_v t.
TRUE_SHARED = np.array([2.0, 0.3])
TRUE_BLOCKS = np.array([[-0.8, 0.1], [-1.5, -0.2], [-0.4, 0.05], [-2.0, 0.3]])
OBSERVED = [
    TRUE_SHARED[0] * np.exp(b * T_S) + TRUE_SHARED[1] + d * T_S + 0.01 * np.sin(7 * T_S + v)
    for v, (b, d) in enumerate(TRUE_BLOCKS)
]


def _block_jacobians(params: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    a, c = params[:2]
    out = []
    for v, (b, d) in enumerate(params[2:].reshape(-1, 2)):
        e = np.exp(b * T_S)
        J_shared = np.column_stack([e, np.ones_like(T_S)])
        J_block = np.column_stack([a * T_S * e, T_S])
        out.append((J_shared, J_block, OBSERVED[v] - (a * e + c + d * T_S)))
    return out


def block_schur(params: np.ndarray) -> SchurSystem:
    return SchurSystem.from_jacobians(_block_jacobians(params))


def block_dense(params: np.ndarray) -> DenseSystem:
    blocks = _block_jacobians(params)
    n_b = len(blocks)
    J = np.zeros((n_b * T_S.size, 2 + 2 * n_b))
    for v, (J_s, J_b, _) in enumerate(blocks):
        J[v * T_S.size : (v + 1) * T_S.size, :2] = J_s
        J[v * T_S.size : (v + 1) * T_S.size, 2 + 2 * v : 4 + 2 * v] = J_b
    return DenseSystem.from_jacobian(J, np.concatenate([b[2] for b in blocks]))


START = np.concatenate([[1.0, 0.0], np.tile([-1.0, 0.0], len(TRUE_BLOCKS))])


@pytest.mark.parametrize("lam", [0.0, 1e-3, 1.0, 1e4])
def test_schur_step_equals_the_dense_step(lam: float) -> None:
    schur = block_schur(START)
    dense = block_dense(START)
    np.testing.assert_allclose(schur.dense().H, dense.H, rtol=1e-13, atol=1e-13)
    d_schur, d_dense = damped_step(schur, lam), damped_step(dense, lam)
    assert np.max(np.abs(d_schur - d_dense)) <= SCHUR_TOL * max(1.0, np.max(np.abs(d_dense)))


def test_schur_solve_equals_the_dense_solve() -> None:
    schur = solve_lm(block_schur, START, _add)
    dense = solve_lm(block_dense, START, _add)
    assert schur.converged and dense.converged
    np.testing.assert_allclose(schur.params, dense.params, rtol=0, atol=SCHUR_TOL)
    assert abs(schur.cost - dense.cost) <= SCHUR_TOL * dense.cost
    np.testing.assert_allclose(schur.params[:2], TRUE_SHARED, atol=0.05)


def test_non_finite_residuals_at_the_start_raise_the_callers_error() -> None:
    def nan_residuals(x: np.ndarray) -> DenseSystem:
        return DenseSystem.from_jacobian(np.eye(2), np.array([np.nan, 1.0]))

    with pytest.raises(NumericalError, match="the test fit cannot start.*NaN or infinite") as info:
        solve_lm(nan_residuals, np.zeros(2), _add, label="the test fit", hint="fix the test")
    assert info.value.exit_code == EXIT_CANNOT_RUN
    assert info.value.hint == "fix the test"


def test_non_finite_jacobian_in_a_schur_block_raises_too() -> None:
    def bad(params: np.ndarray) -> SchurSystem:
        blocks = _block_jacobians(params)
        J_s, J_b, r = blocks[1]
        blocks[1] = (J_s, np.full_like(J_b, np.inf), r)
        with np.errstate(invalid="ignore"):
            return SchurSystem.from_jacobians(blocks)

    with pytest.raises(NumericalError, match="NaN or infinite"):
        solve_lm(bad, START, _add)


def test_a_step_into_non_finite_residuals_is_rejected_and_damped() -> None:
    """log fit: the full Gauss-Newton step from x = 10 lands at x < 0 where log is NaN."""
    target = np.log(0.01)

    def log_fit(x: np.ndarray) -> DenseSystem:
        with np.errstate(invalid="ignore", divide="ignore"):
            return DenseSystem.from_jacobian(np.array([[1.0 / x[0]]]), np.array([target - np.log(x[0])]))

    out = solve_lm(log_fit, np.array([10.0]), _add, damping=Damping(initial=1e-6))
    assert out.converged
    np.testing.assert_allclose(out.params, [0.01], rtol=1e-9)


def test_a_direction_the_residuals_do_not_see_stays_put() -> None:
    """A singular J^T J (parameter 2 has no effect): damping keeps the step finite; that parameter never
    moves."""

    def blind(x: np.ndarray) -> DenseSystem:
        system = exponential(x[:3])
        H = np.zeros((4, 4))
        H[:3, :3] = system.H
        return DenseSystem(system.cost, H, np.concatenate([system.g, [0.0]]))

    out = solve_lm(blind, np.array([1.0, -0.5, 0.0, 42.0]), _add)
    assert out.converged
    np.testing.assert_allclose(out.params, [3.0, -1.3, 0.5, 42.0], atol=1e-9)


def test_steps_that_never_lower_the_cost_stop_on_the_damping_ceiling_at_the_start() -> None:
    def uphill(x: np.ndarray) -> DenseSystem:  # the Jacobian's sign is wrong: every step climbs
        return DenseSystem.from_jacobian(np.array([[-1.0]]), np.array([1.0 - x[0]]))

    out = solve_lm(uphill, np.array([0.0]), _add, damping=Damping(ceiling=1e3))
    assert (out.stop, out.converged) == ("damping", False)
    assert out.params[0] == 0.0 and out.cost == 1.0


def test_the_iteration_cap_is_reported() -> None:
    out = solve_lm(rosenbrock, np.array([-1.2, 1.0]), _add, max_iterations=3)
    assert (out.stop, out.converged, out.iterations) == ("iterations", False, 3)
    assert out.cost < rosenbrock(np.array([-1.2, 1.0])).cost


def test_a_step_below_the_step_tolerance_stops_without_moving() -> None:
    truth = np.array([3.0, -1.3, 0.5])
    out = solve_lm(exponential, truth + 1e-14, _add, step_tolerance=1e-9)
    assert (out.stop, out.converged, out.iterations) == ("step", True, 1)
    np.testing.assert_array_equal(out.params, truth + 1e-14)


def test_a_step_that_raises_the_cost_only_by_rounding_is_the_minimum() -> None:
    """The cost rule works both ways: a trial worse by less than relative_tolerance stops, unapplied."""

    def flat(x: np.ndarray) -> DenseSystem:  # the model says 'go right', the cost rises by 1e-15 of itself
        return DenseSystem(1.0 + 1e-15 * abs(x[0]), np.eye(1), np.ones(1))

    out = solve_lm(flat, np.array([0.0]), _add, relative_tolerance=1e-12)
    assert (out.stop, out.converged, out.iterations) == ("cost", True, 1)
    assert out.params[0] == 0.0
    worse = solve_lm(flat, np.array([0.0]), _add, relative_tolerance=1e-17, damping=Damping(ceiling=1.0))
    assert (worse.stop, worse.converged) == ("damping", False)


def test_dense_equations_regrouped_by_block_give_the_dense_step() -> None:
    """SchurSystem.from_dense on an interleaved layout (blocks between shared parameters, as the rig has
    it)."""
    dense = block_dense(START)
    order = np.array([2, 3, 0, 4, 5, 6, 7, 8, 9, 1])  # block 0, a, blocks 1-3, c
    H, g = dense.H[np.ix_(order, order)], dense.g[order]
    where = np.argsort(order)
    shared = where[:2]
    blocks = where[2:].reshape(-1, 2)
    schur = SchurSystem.from_dense(DenseSystem(dense.cost, H, g), shared, blocks)
    for lam in (1e-3, 10.0):
        delta = damped_step(schur, lam)
        step = np.zeros(10)
        step[shared], step[blocks.ravel()] = delta[:2], delta[2:]
        np.testing.assert_allclose(
            step, damped_step(DenseSystem(dense.cost, H, g), lam), rtol=0, atol=SCHUR_TOL
        )
