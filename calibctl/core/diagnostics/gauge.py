"""Metric-gauge watchdog: the 60 s median of wheel-odometry distance over VIO distance (seed chapter 0).

A gauge fault (board square size, wheel radius, stereo baseline) has no residual signature; the only
instrument that sees it compares two distances whose metres come from physically different sources.
Per window of ``window_s`` seconds we take every moving sample's ratio wheel_step / vio_step and report

    median   the window's verdict value (the median ignores a single wheel-lock outlier)
    spread   1.4826 * MAD of the per-sample ratios (a robust standard deviation)

Warn outside 0.99-1.01, alarm outside 0.98-1.02. The spread is what tells the two causes apart:
wheel slip is noisy and one-directional (the wheel over-reports: ratio > 1, spread comparable to or
larger than the shift); a gauge error is a constant factor with almost no spread (shift >> spread,
the same in every window). Two measurements detect, three localise: which of the two sensors is
wrong needs a third, independent length (a tape-measured 10.000 m course).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.errors import InputError

WARN_BAND = (0.99, 1.01)
ALARM_BAND = (0.98, 1.02)
MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class GaugeWindow:
    start_s: float
    end_s: float
    n_samples: int  # moving samples used
    median_ratio: float | None
    spread: float | None  # robust sigma of per-sample ratios
    mean_ratio: float | None
    frac_above_one: float | None
    level: str  # "ok" | "warn" | "alarm" | "no motion"


@dataclass(frozen=True)
class GaugeReport:
    windows: list[GaugeWindow]
    window_s: float
    level: str  # worst window level
    first_alarm_s: float | None
    median_of_windows: float
    spread_of_windows: float  # std of window medians (how constant the ratio is over time)
    median_spread: float  # median within-window spread
    diagnosis: str
    tail_unused_s: float
    n_stationary: int


def steps_from_cumulative(distance_m: np.ndarray) -> np.ndarray:
    """Per-sample increments (n,) of a cumulative distance (n,); the first sample has no step (0)."""
    d = np.asarray(distance_m, dtype=np.float64)
    return np.concatenate([[0.0], np.diff(d)])


def level_of(ratio: float) -> str:
    if not ALARM_BAND[0] <= ratio <= ALARM_BAND[1]:
        return "alarm"
    if not WARN_BAND[0] <= ratio <= WARN_BAND[1]:
        return "warn"
    return "ok"


def _window(t0: float, t1: float, ratios: np.ndarray, min_samples: int) -> GaugeWindow:
    if ratios.size < min_samples:
        return GaugeWindow(t0, t1, int(ratios.size), None, None, None, None, "no motion")
    med = float(np.median(ratios))
    spread = MAD_TO_SIGMA * float(np.median(np.abs(ratios - med)))
    return GaugeWindow(
        t0,
        t1,
        int(ratios.size),
        med,
        spread,
        float(np.mean(ratios)),
        float(np.mean(ratios > 1.0)),
        level_of(med),
    )


def _diagnose(level: str, med: float, spread_windows: float, spread_within: float) -> str:
    if level == "ok":
        return (
            f"ok: wheel/VIO = {med:.4f}, inside 0.99-1.01 (within-window spread {spread_within:.4f}); "
            "the metric gauges agree"
        )
    shift = abs(med - 1.0)
    if spread_within < shift and spread_windows < 0.5 * shift:
        who = "wheel reads long or VIO reads short" if med > 1.0 else "wheel reads short or VIO reads long"
        return (
            f"gauge error: a constant factor {med:.4f} ({who}) with almost no spread "
            f"({spread_within:.4f} per sample, {spread_windows:.4f} between windows). Suspect a metric "
            "gauge (board square size, wheel radius, stereo baseline); drive a tape-measured 10.000 m "
            "course to find which sensor disagrees with the tape"
        )
    direction = "the wheel over-reports (slip)" if med > 1.0 else "the wheel under-reports"
    return (
        f"noisy ratio: median {med:.4f} with per-sample spread {spread_within:.4f} "
        f"({spread_windows:.4f} between windows) - {direction}; wheel slip or surface, not a constant gauge "
        "factor. Check tyres and floor before touching a calibration"
    )


def gauge_ratio(
    t_s: np.ndarray,
    wheel_step_m: np.ndarray,
    vio_step_m: np.ndarray,
    window_s: float = 60.0,
    min_step_m: float = 1e-4,
    min_samples: int = 10,
) -> GaugeReport:
    """Windowed wheel/VIO distance ratio. All arrays (n,); steps are per-sample distances in metres.

    Samples whose VIO step is below ``min_step_m`` are stationary and skipped (a ratio of two tiny
    numbers is noise). Only full windows are used; the unused tail is reported. Raises InputError when
    the log is shorter than one window or no window has motion.
    """
    t = np.asarray(t_s, dtype=np.float64)
    wheel = np.asarray(wheel_step_m, dtype=np.float64)
    vio = np.asarray(vio_step_m, dtype=np.float64)
    span = float(t[-1] - t[0]) if t.size else 0.0
    n_windows = int(np.floor(span / window_s + 1e-9))
    if n_windows < 1:
        raise InputError(
            f"the log covers {span:.1f} s; one {window_s:g} s window needs at least {window_s:g} s",
            hint="record a longer drive or pass a shorter --window-s",
        )
    moving = vio >= min_step_m
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(moving, wheel / np.where(moving, vio, 1.0), np.nan)
    idx = np.minimum(np.floor((t - t[0]) / window_s).astype(np.int64), n_windows)  # n_windows = the tail
    windows = [
        _window(t[0] + k * window_s, t[0] + (k + 1) * window_s, ratio[(idx == k) & moving], min_samples)
        for k in range(n_windows)
    ]
    scored = [w for w in windows if w.median_ratio is not None]
    if not scored:
        raise InputError(
            f"no {window_s:g} s window has {min_samples} moving samples (VIO steps >= {min_step_m} m)",
            hint="the robot must drive during the log; a parked robot has no distance to compare",
        )
    order = {"ok": 0, "warn": 1, "alarm": 2}
    level = max((w.level for w in scored), key=order.__getitem__)
    first_alarm = next((w.start_s for w in scored if w.level == "alarm"), None)
    meds = np.array([w.median_ratio for w in scored])
    med = float(np.median(meds))
    spread_windows = float(np.std(meds, ddof=1)) if meds.size > 1 else 0.0
    spread_within = float(np.median([w.spread for w in scored]))
    tail = span - n_windows * window_s
    return GaugeReport(
        windows,
        window_s,
        level,
        first_alarm,
        med,
        spread_windows,
        spread_within,
        _diagnose(level, med, spread_windows, spread_within),
        float(tail),
        int(np.count_nonzero(~moving)),
    )
