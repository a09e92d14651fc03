"""The fault injector reproduces the seed's chapter 4/5 per-fault pixel numbers and is deterministic."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.diagnostics import faults


def _res(fault, magnitude, r=0.0, inv_z=0.0, speed=0.0, row=0.0):
    arr = lambda v: np.atleast_1d(np.asarray(v, dtype=float))  # noqa: E731
    return faults.fault_residual_px(fault, magnitude, arr(r), arr(inv_z), arr(speed), arr(row))


def test_seed_pixel_numbers_of_each_fault():
    assert _res("focal", 0.02, r=[160.0, 400.0]) == pytest.approx([3.20, 8.00])  # experiment 5
    assert _res("k1", 0.02, r=[160.0, 460.0]) == pytest.approx([0.128, 3.042], abs=1e-3)  # experiment 6
    assert _res("rotation", 1.0) == pytest.approx([13.964], abs=1e-3)  # experiment 2
    assert _res("principal-point", 10.0) == pytest.approx([10.0])  # experiment 7
    assert _res("translation", 0.02, inv_z=[0.5, 0.05]) == pytest.approx([8.0, 0.8])  # experiment 3
    assert _res("time-offset", 0.0184, speed=[240.0, 460.0]) == pytest.approx([4.416, 8.464])  # experiment 4
    # 20 us/row at row 900 is an 18.0 ms lag: at 240 px/s that is 4.32 px (chapter 4 (e))
    assert _res("rolling-shutter", 20e-6, speed=240.0, row=900.0) == pytest.approx([240.0 * 0.018])
    assert _res("gauge", 0.92, r=300.0) == pytest.approx([0.0])  # chapter 0: no residual at all


def test_unknown_fault_is_rejected():
    with pytest.raises(ValueError, match="unknown fault 'skew'"):
        _res("skew", 1.0)


def test_buffer_is_deterministic_and_shaped_for_triage():
    a = faults.synth_residual_buffer(
        "focal", 0.02, seed=3, n_keyframes=20, features_per_keyframe=10, n_cameras=2
    )
    b = faults.synth_residual_buffer(
        "focal", 0.02, seed=3, n_keyframes=20, features_per_keyframe=10, n_cameras=2
    )
    c = faults.synth_residual_buffer(
        "focal", 0.02, seed=4, n_keyframes=20, features_per_keyframe=10, n_cameras=2
    )
    assert set(a) == {
        "residual_px",
        "radius_px",
        "image_speed_px_s",
        "inv_range_per_m",
        "row",
        "keyframe",
        "camera",
    }
    assert all(v.shape == (400,) for v in a.values())
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not np.array_equal(a["residual_px"], c["residual_px"])
    assert sorted(set(a["camera"].tolist())) == ["cam0", "cam1"]
    ranges_m = 1.0 / a["inv_range_per_m"]
    nearest = faults.STRUCTURE_RANGE_M[
        np.argmin(np.abs(np.log(ranges_m[:, None] / faults.STRUCTURE_RANGE_M)), axis=1)
    ]
    assert np.all(np.abs(ranges_m / nearest - 1.0) < 0.3)  # every feature sits on one of the six structures
    assert a["row"].min() >= 0 and a["row"].max() <= 959


def test_fault_goes_into_cam0_only_and_noise_has_the_seed_correlation():
    buf = faults.synth_residual_buffer("principal-point", 10.0, noise_px=0.3, seed=1, n_cameras=2)
    cam0, cam1 = buf["camera"] == "cam0", buf["camera"] == "cam1"
    assert buf["residual_px"][cam0].mean() == pytest.approx(10.0, abs=0.05)
    clean = buf["residual_px"][cam1]
    assert clean.std() == pytest.approx(0.3, rel=0.03)
    kf = buf["keyframe"][cam1]
    means = np.bincount(kf, weights=clean) / np.bincount(kf)
    # var(keyframe mean) = sigma^2 (rho + (1 - rho) / m) with rho = 0.05, m = 80
    assert means.var() == pytest.approx(0.09 * (0.05 + 0.95 / 80), rel=0.2)


def test_odometry_gauge_scale_and_slip():
    odo = faults.synth_odometry(gauge_scale=0.92, slip_std=0.01, duration_s=120.0, seed=2)
    moving = odo["vio_distance_m"] > 0
    ratio = odo["wheel_distance_m"][moving] / odo["vio_distance_m"][moving]
    assert np.median(ratio) == pytest.approx(1.0 / 0.92, rel=1e-3)
    assert ratio.std() == pytest.approx(0.0102, rel=0.15)
    assert (~moving).any()  # it stops now and then


def test_rate_logs_follow_the_sign_convention():
    gyro, cam = faults.synth_rate_logs(td_s=0.05, duration_s=4.0, noise_frac=0.0, seed=0)
    # camera stamped t measured the rate the gyro saw at t + td
    expected = faults.synth_rate_signal(cam["t_s"] + 0.05, 0, "dance")
    assert cam["rate_rad_s"] == pytest.approx(expected)
    assert gyro["rate_rad_s"] == pytest.approx(faults.synth_rate_signal(gyro["t_s"], 0, "dance"))
