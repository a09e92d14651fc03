"""Camera-IMU time offset: the chapter 3 example, the sign convention, refusals, drift and honest sigma."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.diagnostics.faults import synth_rate_logs
from calibctl.core.diagnostics.timeoffset import (
    OffsetConfig,
    estimate_drift,
    estimate_time_offset,
    normalized_xcorr,
    parabolic_vertex,
)
from calibctl.errors import InputError

TD_SEED_S = 0.0184


def _estimate(gyro, cam, **cfg):
    return estimate_time_offset(
        gyro["t_s"], gyro["rate_rad_s"], cam["t_s"], cam["rate_rad_s"], OffsetConfig(**cfg)
    )


def test_chapter3_example_18_4_ms_at_200_hz_over_3_s_within_0_05_ms():
    """True 18.4 ms, both streams at 200 Hz (5 ms grid), 3 s, 1% noise (a calibration dance with
    reversals)."""
    gyro, cam = synth_rate_logs(
        td_s=TD_SEED_S, duration_s=3.0, gyro_hz=200.0, camera_hz=200.0, noise_frac=0.01, seed=0
    )
    est = _estimate(gyro, cam)
    assert est.refused is None
    assert est.rate_hz == pytest.approx(200.0)
    assert est.integer_lag == 4  # the grid answer, 20.0 ms: 1.6 ms wrong (the seed's "lag -4" in its sign)
    assert abs(est.subsample) < 0.5  # a vertex inside the three points, or it is a reflection
    assert est.subsample < 0  # the refinement pulls toward zero lag, as in the seed
    assert abs(est.td_s - TD_SEED_S) < 0.05e-3
    assert abs(est.td_s - TD_SEED_S) < abs(est.integer_lag / est.rate_hz - TD_SEED_S) / 10.0


def test_parabolic_vertex_formula():
    for vertex in (-0.45, -0.323, 0.0, 0.2, 0.49):
        y = [-((d - vertex) ** 2) * 3.0 + 1.0 for d in (-1.0, 0.0, 1.0)]
        assert parabolic_vertex(*y) == pytest.approx(vertex, abs=1e-12)


@pytest.mark.parametrize("td_s", [-0.031, -0.0184, 0.0, 0.0075, 0.0184, 0.052])
def test_sign_convention_t_gyro_equals_t_camera_plus_td(td_s):
    gyro, cam = synth_rate_logs(td_s=td_s, duration_s=6.0, camera_hz=30.0, noise_frac=0.01, seed=3)
    est = _estimate(gyro, cam)
    assert est.td_s == pytest.approx(td_s, abs=4 * est.sigma_s + 1e-5)
    # applying the correction the convention names (add td to camera stamps) aligns the two streams
    corrected_t = cam["t_s"] + est.td_s
    inside = (corrected_t > gyro["t_s"][0]) & (corrected_t < gyro["t_s"][-1])
    gyro_at = np.interp(corrected_t[inside], gyro["t_s"], gyro["rate_rad_s"])
    wrong_at = np.interp(cam["t_s"][inside] - est.td_s, gyro["t_s"], gyro["rate_rad_s"])
    err = np.abs(gyro_at - cam["rate_rad_s"][inside]).mean()
    assert err < 0.02
    if abs(td_s) > 0.005:
        assert np.abs(wrong_at - cam["rate_rad_s"][inside]).mean() > 3 * err


def test_gain_and_bias_of_the_camera_rate_do_not_move_the_peak():
    gyro, cam = synth_rate_logs(td_s=TD_SEED_S, duration_s=5.0, camera_hz=30.0, noise_frac=0.01, seed=7)
    scaled = {"t_s": cam["t_s"], "rate_rad_s": 0.37 * cam["rate_rad_s"] + 0.8}
    assert _estimate(gyro, scaled).td_s == pytest.approx(_estimate(gyro, cam).td_s, abs=1e-12)


def test_jackknife_sigma_matches_the_actual_scatter():
    errors, sigmas = [], []
    for seed in range(24):
        gyro, cam = synth_rate_logs(
            td_s=TD_SEED_S, duration_s=10.0, camera_hz=200.0, noise_frac=0.05, seed=seed
        )
        est = _estimate(gyro, cam)
        errors.append(est.td_s - TD_SEED_S)
        sigmas.append(est.sigma_s)
    ratio = np.sqrt(np.mean(np.square(errors))) / np.sqrt(np.mean(np.square(sigmas)))
    assert 0.6 < ratio < 1.6  # neither over- nor under-confident by more than the jackknife's own scatter


def test_refuses_a_constant_turn_rate():
    t = np.arange(0.0, 5.0, 0.005)
    rng = np.random.default_rng(0)
    est = estimate_time_offset(t, 0.3 + rng.normal(0, 0.003, t.size), t, 0.3 + rng.normal(0, 0.003, t.size))
    assert est.td_s is None
    assert "varies by only" in est.refused and "pin td" in est.refused


def test_refuses_signals_that_do_not_correlate():
    gyro, _ = synth_rate_logs(duration_s=5.0, seed=1)
    _, cam = synth_rate_logs(duration_s=5.0, seed=2)
    est = _estimate(gyro, cam)
    assert est.td_s is None
    assert est.refused and ("barely correlate" in est.refused or "edge" in est.refused)


def test_refuses_a_peak_on_the_edge_of_the_search_window():
    gyro, cam = synth_rate_logs(td_s=0.15, duration_s=6.0, seed=4)
    est = _estimate(gyro, cam, max_lag_s=0.05)
    assert est.td_s is None and "edge" in est.refused and "--max-lag-s" in est.refused


def test_refuses_when_sigma_exceeds_the_gate():
    gyro, cam = synth_rate_logs(
        td_s=TD_SEED_S, duration_s=2.0, camera_hz=30.0, noise_frac=0.6, seed=5, profile="slalom"
    )
    est = _estimate(gyro, cam, max_sigma_s=0.0005)
    assert est.td_s is not None and est.sigma_s > 0.0005
    assert "standard error" in est.refused


def test_logs_that_do_not_overlap_are_an_input_error():
    gyro, cam = synth_rate_logs(duration_s=3.0, seed=0)
    later = {"t_s": cam["t_s"] + 100.0, "rate_rad_s": cam["rate_rad_s"]}
    with pytest.raises(InputError, match="do not overlap in time"):
        _estimate(gyro, later)
    with pytest.raises(InputError, match=r"overlap for 0.495 s; a \+/-0.2 s search needs at least 1 s"):
        _estimate(gyro, {"t_s": cam["t_s"] + 2.5, "rate_rad_s": cam["rate_rad_s"]})


def test_drift_of_40_ppm_is_measured_in_ppm():
    gyro, cam = synth_rate_logs(
        td_s=0.010, duration_s=600.0, camera_hz=30.0, noise_frac=0.02, drift_ppm=40.0, seed=1
    )
    drift = estimate_drift(gyro["t_s"], gyro["rate_rad_s"], cam["t_s"], cam["rate_rad_s"], window_s=60.0)
    assert drift.refused is None
    lo, hi = drift.ci_ppm
    assert lo < 40.0 < hi
    assert drift.drift_ppm == pytest.approx(40.0, abs=2.0)
    assert drift.fit.coef[0] == pytest.approx(0.010, abs=5e-4)  # td at t = 0


def test_no_drift_gives_an_interval_around_zero():
    gyro, cam = synth_rate_logs(td_s=0.010, duration_s=300.0, camera_hz=30.0, noise_frac=0.02, seed=2)
    drift = estimate_drift(gyro["t_s"], gyro["rate_rad_s"], cam["t_s"], cam["rate_rad_s"], window_s=30.0)
    assert drift.ci_ppm[0] < 0.0 < drift.ci_ppm[1]


def test_drift_needs_three_windows():
    gyro, cam = synth_rate_logs(duration_s=50.0, camera_hz=30.0, seed=0)
    with pytest.raises(InputError, match="gives 1 window"):
        estimate_drift(gyro["t_s"], gyro["rate_rad_s"], cam["t_s"], cam["rate_rad_s"], window_s=30.0)


def test_normalized_xcorr_of_a_shifted_copy_peaks_at_the_shift():
    rng = np.random.default_rng(0)
    a = rng.normal(size=500)
    b = np.roll(a, 7)  # b[i + 7] = a[i]
    lags, ncc = normalized_xcorr(a, b, 10)
    assert lags[np.argmax(ncc)] == 7 and ncc.max() == pytest.approx(1.0)
