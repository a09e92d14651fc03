"""Metric-gauge watchdog: slip does not alarm, a 23/25 mm gauge error alarms from the first window."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.diagnostics.faults import synth_odometry
from calibctl.core.diagnostics.gauge import gauge_ratio, level_of, steps_from_cumulative
from calibctl.errors import InputError


def _gauge(odo, **kw):
    return gauge_ratio(odo["t_s"], odo["wheel_distance_m"], odo["vio_distance_m"], **kw)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_percent_zero_mean_slip_does_not_alarm(seed):
    rep = _gauge(synth_odometry(gauge_scale=1.0, slip_std=0.01, duration_s=900.0, seed=seed))
    assert rep.level == "ok"
    assert rep.first_alarm_s is None
    assert all(abs(w.median_ratio - 1.0) < 0.002 for w in rep.windows)
    assert rep.median_spread == pytest.approx(0.0102, rel=0.1)  # the slip shows up as spread, not shift


@pytest.mark.parametrize("believed_over_true", [23.0 / 25.0, 25.0 / 23.0])
def test_a_23_25_mm_gauge_error_alarms_from_the_first_window(believed_over_true):
    rep = _gauge(synth_odometry(gauge_scale=believed_over_true, slip_std=0.01, duration_s=600.0, seed=4))
    assert rep.level == "alarm"
    assert rep.first_alarm_s == 0.0
    assert all(w.level == "alarm" for w in rep.windows)
    assert rep.median_of_windows == pytest.approx(1.0 / believed_over_true, rel=1e-3)  # 1.087 or 0.920
    assert rep.spread_of_windows < 0.001  # constant: almost no spread between windows
    assert rep.diagnosis.startswith("gauge error: a constant factor")
    assert "tape-measured 10.000 m" in rep.diagnosis


def test_one_directional_slip_reads_as_noise_not_as_a_gauge():
    odo = synth_odometry(gauge_scale=1.0, slip_std=0.01, duration_s=600.0, seed=5)
    rng = np.random.default_rng(0)
    slipping = rng.random(odo["t_s"].size) < 0.5
    odo["wheel_distance_m"][slipping] *= 1.05  # the wheel spins: over-reports, never under-reports
    rep = _gauge(odo)
    assert rep.level in ("warn", "alarm")
    assert rep.median_spread > abs(rep.median_of_windows - 1.0)
    assert rep.diagnosis.startswith("noisy ratio") and "over-reports" in rep.diagnosis


def test_a_wheel_lock_outlier_moves_the_mean_not_the_median():
    odo = synth_odometry(gauge_scale=1.0, slip_std=0.01, duration_s=120.0, seed=6)
    odo["wheel_distance_m"][1000:1010] *= 50.0  # ten samples of a locked-then-released wheel
    rep = _gauge(odo)
    first = rep.windows[0]
    assert first.level == "ok" and abs(first.median_ratio - 1.0) < 0.002
    assert first.mean_ratio > 1.02  # the mean would have alarmed


def test_levels_at_the_band_edges():
    assert level_of(1.0) == "ok" and level_of(1.0095) == "ok"
    assert level_of(0.985) == "warn" and level_of(1.015) == "warn"
    assert level_of(0.979) == "alarm" and level_of(1.087) == "alarm"


def test_stationary_samples_are_skipped_and_counted():
    odo = synth_odometry(duration_s=200.0, seed=1)
    rep = _gauge(odo)
    assert rep.n_stationary == int(np.count_nonzero(odo["vio_distance_m"] < 1e-4))
    assert rep.n_stationary > 0
    assert rep.tail_unused_s == pytest.approx(200.0 - 0.02 - 180.0)


def test_cumulative_distances_become_steps():
    assert steps_from_cumulative(np.array([0.0, 0.5, 1.5, 1.5])).tolist() == [0.0, 0.5, 1.0, 0.0]


def test_a_log_shorter_than_one_window_is_refused():
    odo = synth_odometry(duration_s=30.0, seed=1)
    with pytest.raises(InputError, match=r"covers 30.0 s; one 60 s window needs at least 60 s"):
        _gauge(odo)


def test_a_parked_robot_is_refused():
    t = np.arange(0.0, 120.0, 0.02)
    zeros = np.zeros_like(t)
    with pytest.raises(InputError, match="no 60 s window has 10 moving samples"):
        gauge_ratio(t, zeros, zeros)
