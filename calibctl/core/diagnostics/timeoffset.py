"""Camera-IMU time offset by normalised cross-correlation of two angular-rate signals (seed chapter 3).

Sign convention (tested): ``td`` is the number of seconds to ADD to camera timestamps to put them on
the gyro clock,

    t_gyro = t_camera + td        i.e.   camera_rate(t) ~ gain * gyro_rate(t + td) + bias.

Positive td: the camera stamps its frames td too early (the chapter 3 convention "the camera reports
t, the frame was really captured at t + td"); the triage time-offset channel uses the same sign.

Steps: both streams are linearly resampled onto one grid over their overlap; c(L) = NCC(camera[i],
gyro[i + L]) for integer lags |L| <= max_lag (gain- and bias-invariant, so a gyro scale error cannot
move the peak); the integer peak is refined by the parabola through it and its neighbours,
delta = (y0 - y2) / (2 (y0 - 2 y1 + y2)), and td = (L_peak + delta) / rate.

Uncertainty: a delete-one-block jackknife. The overlap is cut into K (3..10) contiguous blocks of
camera samples; the whole estimate (NCC at every lag, argmax, parabola) is repeated K times with one
block left out, and sigma_td = sqrt((K-1)/K * sum (td_k - mean td_k)^2), with a Student t_{K-1}
interval. This measures the scatter of the estimator actually used - noise on both streams,
resampling of a slow camera onto the grid, parabola error - instead of assuming white noise (a
Gauss-Newton bound built from a differentiated noisy gyro under-states it several-fold).

Refusals (the data cannot pin td; exit 1): rate variation below ``min_rate_std`` (a constant turn is
as useless as standing still), peak NCC below ``min_peak_ncc``, peak on the edge of the lag window,
or sigma_td above ``max_sigma_s`` (chapter 3's 2 ms gate).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibctl.core.diagnostics.regression import LinearFit, fit_line
from calibctl.core.diagnostics.student_t import t_critical
from calibctl.errors import InputError


@dataclass(frozen=True)
class OffsetConfig:
    rate_hz: float | None = None  # default: the faster stream's median rate
    max_lag_s: float = 0.2
    min_rate_std: float = 0.025  # rad/s of variation; 20 px/s at f = 800 px (chapter 3 gate)
    min_peak_ncc: float = 0.5
    max_sigma_s: float = 0.002


JACKKNIFE_BLOCKS = 10
MIN_BLOCK_S = 0.25


@dataclass
class OffsetEstimate:
    td_s: float | None
    sigma_s: float | None
    refused: str | None
    rate_hz: float
    overlap_s: tuple[float, float]
    n_samples: int
    rate_std: float = 0.0
    n_blocks: int = 0
    ci_s: tuple[float, float] | None = None
    peak_ncc: float | None = None
    integer_lag: int | None = None
    subsample: float | None = None
    lags_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ncc: np.ndarray = field(default_factory=lambda: np.zeros(0))


def median_rate_hz(t_s: np.ndarray) -> float:
    return float(1.0 / np.median(np.diff(np.asarray(t_s, dtype=np.float64))))


def parabolic_vertex(y0: float, y1: float, y2: float) -> float:
    """Offset (in samples, relative to the middle point) of the vertex of the parabola through
    (-1, y0), (0, y1), (1, y2). Seed chapter 3: delta = (y0 - y2) / (2 (y0 - 2 y1 + y2))."""
    return (y0 - y2) / (2.0 * (y0 - 2.0 * y1 + y2))


def _lag_block_sums(
    a: np.ndarray, b: np.ndarray, max_lag: int, n_blocks: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per-lag, per-block sums (n, Sx, Sy, Sxx, Syy, Sxy) of the pairs (a[i], b[i + L]); shape (lags, blocks,
    6).

    Blocks partition the index i of ``a`` (the camera), so deleting a block removes the same camera
    samples at every lag.
    """
    n = a.size
    lags = np.arange(-max_lag, max_lag + 1)
    edges = np.linspace(0, n, n_blocks + 1).astype(np.int64)
    sums = np.zeros((lags.size, n_blocks, 6))
    for j, lag in enumerate(lags.tolist()):
        lo, hi = max(0, -lag), n - max(0, lag)
        x, y = a[lo:hi], b[lo + lag : hi + lag]
        starts = np.clip(edges[:-1], lo, hi) - lo
        for q, terms in enumerate((np.ones_like(x), x, y, x * x, y * y, x * y)):
            cs = np.concatenate([[0.0], np.cumsum(terms)])
            sums[j, :, q] = np.diff(np.append(cs[starts], cs[-1]))
    return lags, sums


def _ncc_from_sums(s: np.ndarray) -> np.ndarray:
    """NCC per lag from summed statistics s (lags, 6)."""
    m, sx, sy, sxx, syy, sxy = (s[:, q] for q in range(6))
    cov = sxy - sx * sy / m
    den = np.sqrt(np.maximum(sxx - sx * sx / m, 0.0) * np.maximum(syy - sy * sy / m, 0.0))
    return np.where(den > 0, cov / np.where(den > 0, den, 1.0), 0.0)


def normalized_xcorr(a: np.ndarray, b: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """c(L) = NCC(a[i], b[i + L]) over the overlapping samples, L = -max_lag..max_lag. a, b: (n,)."""
    lags, sums = _lag_block_sums(np.asarray(a, float), np.asarray(b, float), max_lag, 1)
    return lags, _ncc_from_sums(sums.sum(axis=1))


def _refine_peak(lags: np.ndarray, ncc: np.ndarray) -> float | None:
    """Sub-sample lag of the NCC maximum, or None when the peak is on the edge or has no curvature."""
    k = int(np.argmax(ncc))
    if k == 0 or k == ncc.size - 1 or ncc[k - 1] - 2.0 * ncc[k] + ncc[k + 1] >= 0:
        return None
    return float(lags[k] + parabolic_vertex(ncc[k - 1], ncc[k], ncc[k + 1]))


def overlap_of(t_gyro: np.ndarray, t_cam: np.ndarray) -> tuple[float, float]:
    t0, t1 = max(float(t_gyro[0]), float(t_cam[0])), min(float(t_gyro[-1]), float(t_cam[-1]))
    if t1 <= t0:
        raise InputError(
            f"the logs do not overlap in time: gyro covers {t_gyro[0]:.3f}..{t_gyro[-1]:.3f} s, "
            f"camera covers {t_cam[0]:.3f}..{t_cam[-1]:.3f} s",
            hint="both logs must be stamped on clocks that roughly agree (same epoch, seconds)",
        )
    return t0, t1


def _jackknife_sigma(sums: np.ndarray, lags: np.ndarray, rate_hz: float) -> float:
    """Delete-one-block jackknife standard error (s) of the refined peak; sums (lags, blocks, 6)."""
    total = sums.sum(axis=1)
    k = sums.shape[1]
    est = []
    for q in range(k):
        lag = _refine_peak(lags, _ncc_from_sums(total - sums[:, q, :]))
        if lag is None:
            return float("inf")
        est.append(lag / rate_hz)
    est_arr = np.array(est)
    return float(np.sqrt((k - 1) / k * np.sum((est_arr - est_arr.mean()) ** 2)))


def estimate_time_offset(
    t_gyro, rate_gyro, t_cam, rate_cam, cfg: OffsetConfig = OffsetConfig()
) -> OffsetEstimate:
    """td (s) such that t_gyro = t_camera + td. Arrays (n,) and (m,) float64, times increasing (s)."""
    tg, g = np.asarray(t_gyro, dtype=np.float64), np.asarray(rate_gyro, dtype=np.float64)
    tc, c = np.asarray(t_cam, dtype=np.float64), np.asarray(rate_cam, dtype=np.float64)
    t0, t1 = overlap_of(tg, tc)
    rate = cfg.rate_hz or max(median_rate_hz(tg), median_rate_hz(tc))
    need = max(1.0, 4.0 * cfg.max_lag_s)
    if t1 - t0 < need:
        raise InputError(
            f"the logs overlap for {t1 - t0:.3f} s; a +/-{cfg.max_lag_s:g} s search needs at least "
            f"{need:g} s of overlap",
            hint="record a longer motion, or pass a smaller --max-lag-s",
        )
    grid = t0 + np.arange(int(np.floor((t1 - t0) * rate)) + 1) / rate
    a, b = np.interp(grid, tc, c), np.interp(grid, tg, g)
    est = OffsetEstimate(None, None, None, rate, (t0, t1), int(grid.size), rate_std=float(np.std(b)))
    if est.rate_std < cfg.min_rate_std:
        est.refused = (
            f"the gyro rate varies by only {est.rate_std:.4f} rad/s (std) over the overlap; at least "
            f"{cfg.min_rate_std:g} rad/s of variation is needed to pin td - excite with turns and reversals"
        )
        return est
    max_lag = max(1, int(round(cfg.max_lag_s * rate)))
    est.n_blocks = int(np.clip(np.floor((t1 - t0) / MIN_BLOCK_S), 3, JACKKNIFE_BLOCKS))
    lags, sums = _lag_block_sums(a, b, max_lag, est.n_blocks)
    ncc = _ncc_from_sums(sums.sum(axis=1))
    est.lags_s, est.ncc = lags / rate, ncc
    k = int(np.argmax(ncc))
    est.integer_lag, est.peak_ncc = int(lags[k]), float(ncc[k])
    if k == 0 or k == lags.size - 1:
        est.refused = (
            f"the correlation peak sits on the edge of the +/-{cfg.max_lag_s:g} s search window; the "
            "offset may be larger - re-run with a larger --max-lag-s"
        )
        return est
    if est.peak_ncc < cfg.min_peak_ncc:
        est.refused = (
            f"the two rate signals barely correlate (peak NCC {est.peak_ncc:.3f} < {cfg.min_peak_ncc}); "
            "are they the same axis, and did the robot move?"
        )
        return est
    lag = _refine_peak(lags, ncc)
    if lag is None:
        est.refused = "the correlation has no curvature at its peak (flat plateau); td is not pinned"
        return est
    est.subsample = lag - est.integer_lag
    est.td_s = lag / rate
    est.sigma_s = _jackknife_sigma(sums, lags, rate)
    half = t_critical(0.95, est.n_blocks - 1) * est.sigma_s
    est.ci_s = (est.td_s - half, est.td_s + half)
    if not est.sigma_s <= cfg.max_sigma_s:
        est.refused = (
            f"td = {est.td_s * 1e3:.3f} ms but its standard error is {est.sigma_s * 1e3:.3f} ms, above the "
            f"{cfg.max_sigma_s * 1e3:g} ms gate; the motion does not pin td - add rate reversals"
        )
    return est


@dataclass
class DriftEstimate:
    windows: list[tuple[float, OffsetEstimate]]  # (window centre s, estimate)
    fit: LinearFit | None
    drift_ppm: float | None
    se_ppm: float | None
    ci_ppm: tuple[float, float] | None
    refused: str | None


def estimate_drift(
    t_gyro, rate_gyro, t_cam, rate_cam, window_s: float, cfg: OffsetConfig = OffsetConfig()
) -> DriftEstimate:
    """td in consecutive ``window_s`` windows, then td(t) = td0 + drift * t by OLS; drift in ppm (1e-6
    s/s)."""
    tg, g = np.asarray(t_gyro, dtype=np.float64), np.asarray(rate_gyro, dtype=np.float64)
    tc, c = np.asarray(t_cam, dtype=np.float64), np.asarray(rate_cam, dtype=np.float64)
    t0, t1 = overlap_of(tg, tc)
    n_win = int(np.floor((t1 - t0) / window_s + 1e-9))
    if n_win < 3:
        raise InputError(
            f"the logs overlap for {t1 - t0:.1f} s, which gives {n_win} window(s) of {window_s:g} s; a "
            "drift fit needs at least 3",
            hint="use a longer log or a shorter --window",
        )
    windows = []
    for k in range(n_win):
        w0, w1 = t0 + k * window_s, t0 + (k + 1) * window_s
        mg, mc = (tg >= w0) & (tg <= w1), (tc >= w0) & (tc <= w1)
        if mg.sum() < 4 or mc.sum() < 4:
            raise InputError(
                f"window {w0:.1f}..{w1:.1f} s has fewer than 4 samples in one of the logs",
                hint="the logs have a gap; use a longer --window",
            )
        windows.append((0.5 * (w0 + w1), estimate_time_offset(tg[mg], g[mg], tc[mc], c[mc], cfg)))
    good = [(tm, e) for tm, e in windows if e.refused is None]
    if len(good) < 3:
        return DriftEstimate(
            windows,
            None,
            None,
            None,
            None,
            f"only {len(good)} of {n_win} windows pinned td; a drift fit needs at least 3",
        )
    fit = fit_line(np.array([tm for tm, _ in good]), np.array([e.td_s for _, e in good]))
    ci = fit.interval()[1] * 1e6
    return DriftEstimate(
        windows, fit, float(fit.coef[1] * 1e6), float(fit.se[1] * 1e6), (float(ci[0]), float(ci[1])), None
    )
