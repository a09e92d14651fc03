"""Residual triage: each injected fault named and measured, the degeneracy flagged, refusals honest."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibctl.core.diagnostics import faults
from calibctl.core.diagnostics.triage import (
    DEGENERACY_NOTE,
    GAUGE_POINTER,
    TriageConfig,
    triage_by_camera,
    triage_camera,
)
from calibctl.errors import InputError

REL_TOL = 0.05  # the "within 5%"
CHANNEL_OF = {
    "focal": "focal",
    "k1": "k1",
    "translation": "lever_arm",
    "time-offset": "time_offset",
    "rolling-shutter": "line_delay",
    "rotation": "rotation_or_principal_point",
    "principal-point": "rotation_or_principal_point",
}


def _run(buf, **kw):
    return triage_by_camera(
        buf["residual_px"],
        buf["radius_px"],
        buf["image_speed_px_s"],
        buf["inv_range_per_m"],
        buf["row"],
        keyframe=buf.get("keyframe"),
        camera=buf.get("camera"),
        **kw,
    )


def _channel(cam, key):
    return next(c for c in cam.channels if c.spec.key == key)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("fault", ["focal", "k1", "translation", "time-offset", "rolling-shutter"])
def test_each_fault_is_named_alone_and_measured_within_5_percent(fault, seed):
    magnitude = faults.DEFAULT_MAGNITUDE[fault]
    summary = _run(faults.synth_residual_buffer(fault, magnitude, noise_px=0.3, seed=seed))
    cam = summary.cameras[0]
    assert [c.spec.key for c in cam.faults] == [CHANNEL_OF[fault]]
    got = _channel(cam, CHANNEL_OF[fault])
    assert got.value == pytest.approx(magnitude, rel=REL_TOL)
    lo, hi = got.value_ci
    assert lo < got.value < hi
    assert summary.fail
    assert cam.verdict == f"fault: {got.spec.fault}"


@pytest.mark.parametrize(
    ("fault", "magnitude_px"), [("rotation", 800.0 * math.tan(math.radians(1.0))), ("principal-point", 10.0)]
)
def test_rotation_and_principal_point_land_in_the_same_column(fault, magnitude_px):
    summary = _run(faults.synth_residual_buffer(fault, faults.DEFAULT_MAGNITUDE[fault], noise_px=0.3, seed=4))
    cam = summary.cameras[0]
    assert [c.spec.key for c in cam.faults] == ["rotation_or_principal_point"]
    assert DEGENERACY_NOTE in cam.verdict
    got = _channel(cam, "rotation_or_principal_point")
    assert got.coef == pytest.approx(magnitude_px, rel=REL_TOL)  # px: 13.96 for 1 deg, 10 for 10 px
    assert got.value == pytest.approx(math.degrees(math.atan(magnitude_px / 800.0)), rel=REL_TOL)


def test_the_two_degenerate_faults_give_the_same_report():
    """Same seed, same pixel size: rotation and principal point are indistinguishable, digit for digit."""
    rot_deg = math.degrees(math.atan(10.0 / 800.0))
    a = _run(faults.synth_residual_buffer("rotation", rot_deg, seed=9)).cameras[0]
    b = _run(faults.synth_residual_buffer("principal-point", 10.0, seed=9)).cameras[0]
    assert np.allclose(a.joint.coef, b.joint.coef, rtol=0, atol=1e-9)
    assert a.verdict == b.verdict


def test_gauge_fault_has_no_residual_signature():
    summary = _run(faults.synth_residual_buffer("gauge", 0.92, noise_px=0.3, seed=3))
    cam = summary.cameras[0]
    assert cam.faults == []
    assert cam.verdict == GAUGE_POINTER
    assert "calibctl gauge" in cam.verdict
    assert not summary.fail


def test_k1_fault_reports_its_radial_order():
    cam = _run(faults.synth_residual_buffer("k1", 0.02, seed=1)).cameras[0]
    assert cam.radial_order is not None
    assert cam.radial_order["reading"] == "k1 (r^3), not k2 (r^5)"
    assert abs(cam.radial_order["t5"]) < cam.t_critical < abs(cam.radial_order["t3"])


def test_collinear_columns_are_not_attributed_and_their_correlation_is_printed():
    rng = np.random.default_rng(0)
    n_kf, m = 60, 20
    kf = np.repeat(np.arange(n_kf), m)
    z = np.repeat(rng.uniform(1.0, 50.0, n_kf), m)
    inv_z = 1.0 / z
    radius = 40.0 + 400.0 * inv_z + rng.normal(0.0, 0.05, kf.size)  # radius follows 1/Z exactly
    speed = np.repeat(rng.uniform(100.0, 500.0, n_kf), m)
    row = np.repeat(rng.uniform(50.0, 900.0, n_kf), m)
    residual = 16.0 * inv_z + rng.normal(0.0, 0.3, kf.size)  # a lever arm... or a focal error
    cam = triage_camera(residual, radius, speed, inv_z, row, keyframe=kf)
    pair = next(p for p in cam.collinear if {p[0], p[1]} == {"r", "1/Z"})
    assert abs(pair[2]) > 0.995
    focal, lever = _channel(cam, "focal"), _channel(cam, "lever_arm")
    assert lever.status == "collinear" and "fitted together with r" in lever.note
    assert focal.status == "fault" and focal.value is None  # a magnitude, but no attribution
    assert "refusing to attribute" in focal.note and f"{pair[2]:+.4f}" in focal.note
    assert "refusing to attribute" in cam.verdict


def test_a_covariate_that_never_varied_carries_no_information():
    buf = faults.synth_residual_buffer("time-offset", 0.0184, seed=2)
    buf["row"] = np.zeros_like(buf["row"])  # a global-shutter log: no row information
    cam = _run(buf).cameras[0]
    line = _channel(cam, "line_delay")
    assert line.status == "no information" and "row never varied" in line.note
    assert _channel(cam, "time_offset").value == pytest.approx(0.0184, rel=REL_TOL)


def test_aggregation_per_keyframe_stops_shared_errors_faking_confidence():
    """Speed varies between keyframes only and every keyframe shares a 1 px pose error: with keyframes
    the td channel is honest; treating rows as independent shrinks its SE by ~sqrt(rows per keyframe)."""
    rng = np.random.default_rng(21)
    n_kf, m = 80, 64
    kf = np.repeat(np.arange(n_kf), m)
    speed = np.repeat(rng.uniform(50.0, 600.0, n_kf), m)
    radius = rng.uniform(20.0, 500.0, kf.size)
    inv_z = 1.0 / rng.uniform(1.0, 50.0, kf.size)
    row = rng.uniform(0.0, 959.0, kf.size)
    residual = np.repeat(rng.normal(0.0, 1.0, n_kf), m) + rng.normal(0.0, 0.1, kf.size)
    honest = triage_camera(residual, radius, speed, inv_z, row, keyframe=kf)
    naive = triage_camera(residual, radius, speed, inv_z, row, keyframe=None)
    td_honest, td_naive = _channel(honest, "time_offset"), _channel(naive, "time_offset")
    assert honest.n_keyframes == n_kf and naive.n_keyframes == n_kf * m
    assert td_naive.se < td_honest.se / 4.0
    assert td_honest.status != "fault"


def test_significant_but_subpixel_effects_are_not_named():
    buf = faults.synth_residual_buffer("time-offset", 0.0002, noise_px=0.05, seed=5, n_keyframes=800)
    cam = _run(buf).cameras[0]
    td = _channel(cam, "time_offset")
    assert abs(td.t) > cam.t_critical
    assert td.status == "below effect floor" and td.effect_px < 0.5
    assert cam.faults == []


def test_one_bad_camera_raises_the_rms_spread_alarm():
    summary = _run(faults.synth_residual_buffer("translation", 0.02, seed=6, n_cameras=3, n_keyframes=200))
    assert [c.camera for c in summary.cameras] == ["cam0", "cam1", "cam2"]
    assert summary.camera_rms_level == "alarm" and summary.camera_rms_ratio > 2.0
    assert [bool(c.faults) for c in summary.cameras] == [True, False, False]


def test_thermal_drift_is_reported_in_px_per_kelvin():
    rng = np.random.default_rng(8)
    buf = faults.synth_residual_buffer("gauge", 0.92, noise_px=0.3, seed=8)
    temp_kf = rng.uniform(10.0, 40.0, 500)
    temperature = temp_kf[buf["keyframe"]]
    buf["residual_px"] = buf["residual_px"] * (1.0 + 0.05 * (temperature - 10.0))  # RMS grows ~0.015 px/K
    cam = triage_by_camera(
        buf["residual_px"],
        buf["radius_px"],
        buf["image_speed_px_s"],
        buf["inv_range_per_m"],
        buf["row"],
        keyframe=buf["keyframe"],
        temperature_c=temperature,
    ).cameras[0]
    assert cam.thermal["status"] == "fault"
    assert cam.thermal["slope_px_per_k"] == pytest.approx(0.3 * 0.05, rel=0.25)
    assert "thermal drift" in cam.verdict


def test_too_few_keyframes_is_an_input_error():
    buf = faults.synth_residual_buffer("focal", 0.02, seed=1, n_keyframes=8)
    with pytest.raises(InputError, match="8 keyframes; the joint fit of 6 columns needs at least 12"):
        _run(buf)


def test_a_stricter_threshold_changes_the_naming_threshold():
    buf = faults.synth_residual_buffer("focal", 0.02, seed=1)
    loose, strict = _run(buf).cameras[0], _run(buf, cfg=TriageConfig(t_min=1e4)).cameras[0]
    assert loose.t_critical == pytest.approx(4.0) and strict.t_critical == pytest.approx(1e4)
    assert loose.faults and not strict.faults
