"""Uniform cubic B-splines and the block-banded solve their normal equations need (numpy only).

A spline of ``n`` control points c_k (each (d,)) on knots t0 + k dt: on segment i (t0 + i dt <= t <
t0 + (i+1) dt, u = (t - t0)/dt - i) the value is sum_j b_j(u) c_{i+j}, j = 0..3, with the standard
basis matrix below; it is C2 and valid for t in [t0, t0 + (n - 3) dt). Each sample touches four
consecutive control points, so the normal equations over the control points are block-banded: knot k
couples with knots k-3..k+3 only. ``BandedCholesky`` factors that band (blocks of the per-knot
size) and solves with many right-hand sides in O(n) small dense operations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# rows: powers of u (1, u, u^2, u^3); columns: the four control points; times 1/6.
BASIS = (
    np.array([[1.0, 4.0, 1.0, 0.0], [-3.0, 0.0, 3.0, 0.0], [3.0, -6.0, 3.0, 0.0], [-1.0, 3.0, -3.0, 1.0]]) / 6
)


@dataclass(frozen=True)
class Knots:
    """t0_s: the first knot (s); dt_s: knot spacing (s); n: control points."""

    t0_s: float
    dt_s: float
    n: int

    @classmethod
    def covering(cls, t_begin_s: float, t_end_s: float, dt_s: float, margin_s: float) -> Knots:
        t0 = t_begin_s - margin_s
        n = int(np.ceil((t_end_s + margin_s - t0) / dt_s)) + 3
        return cls(t0, dt_s, n)

    @property
    def t_end_s(self) -> float:
        return self.t0_s + (self.n - 3) * self.dt_s

    def locate(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(segment index (m,) int, u (m,) in [0, 1)); stamps outside the valid span are clipped onto the
        end segments (u then leaves [0, 1): the end polynomial extended)."""
        x = (np.asarray(t_s, np.float64) - self.t0_s) / self.dt_s
        i = np.clip(np.floor(x).astype(np.int64), 0, self.n - 4)
        return i, x - i

    def weights(self, u: np.ndarray, derivative: int = 0) -> np.ndarray:
        """(m, 4) basis weights of the four control points for the value or its 1st/2nd time derivative."""
        u = np.asarray(u, np.float64)
        one = np.ones_like(u)
        if derivative == 0:
            powers = np.stack([one, u, u * u, u * u * u], axis=1)
        elif derivative == 1:
            powers = np.stack([0 * one, one, 2 * u, 3 * u * u], axis=1) / self.dt_s
        else:
            powers = np.stack([0 * one, 0 * one, 2 * one, 6 * u], axis=1) / self.dt_s**2
        return powers @ BASIS


def local_controls(ctrl: np.ndarray, segment: np.ndarray) -> np.ndarray:
    """(m, 4, d) the four control points of each sample's segment, from ctrl (n, d)."""
    return ctrl[segment[:, None] + np.arange(4)]


def scatter_band(
    n: int, segment: np.ndarray, H_local: np.ndarray, H_cross: np.ndarray, g_local: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sum per-sample blocks into the band.

    Args:
        n: control points; segment: (m,) first control point of each sample (non-decreasing).
        H_local: (m, 4k, 4k) J_l^T J_l; H_cross: (m, 4k, p) J_l^T J_s; g_local: (m, 4k) J_l^T r.

    Returns:
        band (n, 4, k, k): band[i, d] = block (knot i, knot i + d); cross (n, k, p); g (n, k).
    """
    k = H_local.shape[1] // 4
    p = H_cross.shape[2]
    starts = np.flatnonzero(np.r_[True, segment[1:] != segment[:-1]])
    seg = segment[starts]
    Hl = np.add.reduceat(H_local, starts, axis=0)
    Hc = np.add.reduceat(H_cross, starts, axis=0)
    gl = np.add.reduceat(g_local, starts, axis=0)
    band = np.zeros((n, 4, k, k))
    cross = np.zeros((n, k, p))
    g = np.zeros((n, k))
    for a in range(4):
        rows = slice(a * k, (a + 1) * k)
        cross[seg + a] += Hc[:, rows, :]
        g[seg + a] += gl[:, rows]
        for b in range(a, 4):
            band[seg + a, b - a] += Hl[:, rows, b * k : (b + 1) * k]
    return band, cross, g


def segment_gram(segment: np.ndarray, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sum of J_s^T J_s over each run of equal ``segment`` (non-decreasing), J (m, r, q): (the runs'
    segments (g,), sums (g, q, q)). A run's samples are stacked into one (length x r, q) block and
    multiplied once, not as m small products summed afterwards (ten times faster at 200 Hz, 20 knots/s)."""
    starts = np.flatnonzero(np.r_[True, segment[1:] != segment[:-1]])
    counts = np.diff(np.r_[starts, segment.size])
    stacked = np.zeros((starts.size, int(counts.max()), *J.shape[1:]))
    stacked[
        np.repeat(np.arange(starts.size), counts), np.arange(segment.size) - np.repeat(starts, counts)
    ] = J
    stacked = stacked.reshape(starts.size, -1, J.shape[2])
    return segment[starts], np.transpose(stacked, (0, 2, 1)) @ stacked


class BandedCholesky:
    """L L^T of a symmetric positive definite block-banded matrix, band (n, 4, k, k) as ``scatter_band``
    returns it (only blocks (i, i + d), d = 0..3, are read)."""

    def __init__(self, band: np.ndarray) -> None:
        n, _, k, _ = band.shape
        L = np.zeros((n, 4, k, k))  # L[i, d] = block (i, i - d) of the factor; d = 0 lower triangular
        for i in range(n):
            for d in range(3, 0, -1):
                j = i - d
                if j < 0:
                    continue
                acc = band[j, d].T.copy()
                for e in range(d + 1, 4):
                    if i - e >= 0:
                        acc -= L[i, e] @ L[j, e - d].T
                L[i, d] = np.linalg.solve(L[j, 0], acc.T).T
            diag = band[i, 0] - sum(L[i, d] @ L[i, d].T for d in range(1, 4) if i - d >= 0)
            L[i, 0] = np.linalg.cholesky(diag)
        self.L = L

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x (n, k, m) solving A x = b for b (n, k, m)."""
        L = self.L
        n = L.shape[0]
        y = np.empty_like(b)
        for i in range(n):
            acc = b[i].copy()
            for d in range(1, 4):
                if i - d >= 0:
                    acc -= L[i, d] @ y[i - d]
            y[i] = np.linalg.solve(L[i, 0], acc)
        x = np.empty_like(b)
        for i in range(n - 1, -1, -1):
            acc = y[i].copy()
            for d in range(1, 4):
                if i + d < n:
                    acc -= L[i + d, d].T @ x[i + d]
            x[i] = np.linalg.solve(L[i, 0].T, acc)
        return x
