"""The B-spline pieces: basis weights and derivatives, the banded solve against a dense one."""

from __future__ import annotations

import numpy as np

from calibctl.core.imu.spline import BandedCholesky, Knots, scatter_band, segment_gram


def test_weights_partition_unity_and_differentiate() -> None:
    knots = Knots(0.0, 0.1, 20)
    t = np.linspace(0.0, knots.t_end_s - 1e-9, 57)
    _, u = knots.locate(t)
    assert np.allclose(knots.weights(u).sum(axis=1), 1.0)
    assert np.allclose(knots.weights(u, 1).sum(axis=1), 0.0)
    h = 1e-6
    numeric = (knots.weights(u + h / 0.1) - knots.weights(u - h / 0.1)) / (2 * h)
    assert np.allclose(numeric, knots.weights(u, 1), atol=1e-5)
    numeric2 = (knots.weights(u + h / 0.1, 1) - knots.weights(u - h / 0.1, 1)) / (2 * h)
    assert np.allclose(numeric2, knots.weights(u, 2), atol=1e-3)


def test_banded_cholesky_solves_like_a_dense_solve() -> None:
    rng = np.random.default_rng(3)
    n, k, p, m = 30, 6, 4, 300
    seg = np.sort(rng.integers(0, n - 3, m))
    J = rng.normal(size=(m, 3, 4 * k))
    Js = rng.normal(size=(m, 3, p))
    r = rng.normal(size=(m, 3))
    JT = np.transpose(J, (0, 2, 1))
    band, cross, g = scatter_band(n, seg, JT @ J, JT @ Js, np.einsum("mra,mr->ma", J, r))
    band[:, 0] += 1e-3 * np.eye(k)
    A = 1e-3 * np.eye(n * k)
    G = np.zeros(n * k)
    B = np.zeros((n * k, p))
    for i in range(m):
        cols = np.arange(seg[i] * k, (seg[i] + 4) * k)
        A[np.ix_(cols, cols)] += J[i].T @ J[i]
        G[cols] += J[i].T @ r[i]
        B[cols] += J[i].T @ Js[i]
    x = BandedCholesky(band).solve(np.concatenate([cross, g[:, :, None]], axis=2))
    assert np.allclose(x[:, :, -1].ravel(), np.linalg.solve(A, G), atol=1e-10)
    assert np.allclose(x[:, :, :-1].reshape(n * k, p), np.linalg.solve(A, B), atol=1e-10)


def test_segment_gram_sums_each_runs_products() -> None:
    rng = np.random.default_rng(3)
    segment = np.array([0, 0, 0, 2, 5, 5, 6, 6, 6, 6])  # runs of uneven length, segments skipped
    J = rng.standard_normal((segment.size, 6, 5))
    runs, G = segment_gram(segment, J)
    assert np.array_equal(runs, [0, 2, 5, 6])
    for run, block in zip(runs, G, strict=True):
        mine = J[segment == run]
        assert np.allclose(block, sum(j.T @ j for j in mine))
