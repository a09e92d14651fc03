"""fleet trends' numbers on synthetic series with known slopes: each recovered within its own sigma."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from calibctl.errors import NotFoundError
from calibctl.store.health import HealthRow
from calibctl.workflows.fleet.trends import compute_trends, fit_slope

T0 = datetime(2026, 1, 1, tzinfo=UTC)


def _row(kind: str, day: float, **numbers: float | str) -> HealthRow:
    fields: dict = {
        "rms_px": None,
        "verdict": None,
        "ratio": None,
        "sigma": None,
        "td_ms": None,
        "sigma_ms": None,
        "temperature_c": None,
        **numbers,
    }
    return HealthRow("CAM-A", kind, T0 + timedelta(days=day), **fields)


def test_known_slopes_are_recovered_within_their_sigma() -> None:
    rng = np.random.default_rng(7)
    temps = rng.uniform(-10, 50, 200)
    rms = 0.30 + 0.004 * temps + rng.normal(0, 0.02, temps.size)  # 0.004 px/degC, thermal
    days = np.arange(60.0)
    td_ms = 2.0 + 20e-3 * days * 86400 + rng.normal(0, 5.0, days.size)  # 20 ppm = 20e-3 ms per s
    rows = [
        _row("check", i * 0.3, rms_px=float(r), verdict="pass", temperature_c=float(t))
        for i, (t, r) in enumerate(zip(temps, rms, strict=True))
    ]
    rows += [
        _row("timeoffset", float(d), td_ms=float(v), sigma_ms=5.0, temperature_c=25.0)
        for d, v in zip(days, td_ms, strict=True)
    ]
    t = compute_trends("CAM-A", rows, {})
    s, d = t.rms_vs_temperature_px_per_c, t.td_drift_ppm
    assert s is not None and d is not None
    assert s.n == 200 and 0 < s.sigma < 0.001 and abs(s.slope - 0.004) < 3 * s.sigma
    assert d.n == 60 and 0 < d.sigma < 0.1 and abs(d.slope - 20.0) < 3 * d.sigma
    assert t.td_span_days == pytest.approx(59.0)
    assert [b["from_c"] for b in t.rms_by_temperature] == [-10.0, 0.0, 10.0, 20.0, 30.0, 40.0]
    assert sum(b["n"] for b in t.rms_by_temperature) == 200
    assert t.rms_by_temperature[-1]["mean"] > t.rms_by_temperature[0]["mean"] + 0.15
    assert any("drifts +20" in f and "clock drift" in f for f in t.findings)
    assert any("RMS rises with temperature" in f for f in t.findings)


def test_a_flat_series_raises_no_finding_and_small_series_give_no_slope() -> None:
    rng = np.random.default_rng(3)
    rows = [
        _row(
            "check",
            i,
            rms_px=float(0.3 + rng.normal(0, 0.01)),
            verdict="pass",
            temperature_c=float(20 + i % 15),
        )
        for i in range(100)
    ]
    rows += [
        _row("timeoffset", i, td_ms=float(1.0 + rng.normal(0, 0.1)), sigma_ms=0.1, temperature_c=20.0)
        for i in range(30)
    ]
    t = compute_trends("CAM-A", rows, {})
    assert t.findings == []
    assert t.td_drift_ppm is not None and abs(t.td_drift_ppm.slope) < 5.0
    assert fit_slope(np.array([1.0, 2.0]), np.array([1.0, 2.0])) is None  # n < 3
    assert fit_slope(np.full(5, 20.0), np.arange(5.0)) is None  # no spread in temperature


def test_gauge_triage_and_the_one_bad_camera_the_fleet_mean_hides() -> None:
    rows = [_row("gauge", i, ratio=1.0 + 0.001 * (i - 5), sigma=0.002) for i in range(11)]
    rows += [
        _row("triage", 1, verdict="ok"),
        _row("triage", 2, verdict="ok"),
        _row("triage", 3, verdict="time"),
    ]
    rows += [_row("check", 1, rms_px=0.64, verdict="fail")]
    fleet = {"CAM-A": (0.64, 1), **{f"CAM-{i}": (0.28 + 0.01 * i, 30) for i in range(5)}}
    t = compute_trends("CAM-A", rows, fleet)
    assert t.gauge is not None and t.gauge["median"] == pytest.approx(1.0) and t.gauge["n"] == 11
    assert t.gauge["p05"] < 1.0 < t.gauge["p95"]
    assert t.triage_verdicts == {"ok": 2, "time": 1} and t.check_verdicts == {"fail": 1}
    assert t.fleet is not None and t.fleet["rank"] == 6 and t.fleet["worst"] == "CAM-A"
    assert t.fleet["max_over_min"] == pytest.approx(0.64 / 0.28)
    assert any("this camera is the worst" in f for f in t.findings)


def test_no_reports_is_an_error_naming_the_serial() -> None:
    with pytest.raises(NotFoundError, match="no health reports for CAM-Z"):
        compute_trends("CAM-Z", [], {})
