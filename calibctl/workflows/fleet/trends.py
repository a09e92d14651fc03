"""``fleet trends``: one serial's health as conditionals (seed chapter 6, "the trends"): RMS against
temperature (thermal, reversible), the time offset against time (clock drift, in ppm), and the per-camera RMS
spread (one bad sensor hiding in a fleet aggregate). Each slope is an ordinary least-squares fit with its
1-sigma from the residual scatter and its n; each aggregate comes with the breakdown it would hide (per 10
degC bin).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibctl.errors import NotFoundError
from calibctl.store.health import HealthRow

TEMPERATURE_BIN_C = 10.0
DRIFT_PPM = 5.0
"""Seed chapter 6: a td slope above ~5 ppm is drift, not offset (two free-running crystals reach 40 ppm)."""
SPREAD_RATIO = 2.0
"""Seed chapter 6, mode C: max/min mean RMS across cameras above 2 means one camera is hiding in the mean."""


@dataclass(frozen=True)
class Slope:
    """``y = intercept + slope * (x - x_mean)``: slope in y-units per x-unit, its 1-sigma, n points."""

    slope: float
    sigma: float
    n: int

    def as_json(self) -> dict[str, Any]:
        return {"slope": self.slope, "sigma": self.sigma, "n": self.n}


def fit_slope(x: np.ndarray, y: np.ndarray) -> Slope | None:
    """OLS slope of ``y`` on ``x`` (both shape (n,)) with its standard error; None with n < 3 or no spread in
    x."""
    n = int(x.size)
    if n < 3:
        return None
    xc = x - x.mean()
    sxx = float(xc @ xc)
    if sxx <= 0 or not math.isfinite(sxx):
        return None
    slope = float(xc @ (y - y.mean())) / sxx
    residual = y - y.mean() - slope * xc
    return Slope(slope, math.sqrt(float(residual @ residual) / (n - 2) / sxx), n)


@dataclass
class Trends:
    """One serial's trends (see the module docstring); None where there is too little data for the number."""

    serial: str
    counts: dict[str, int]
    rms_vs_temperature_px_per_c: Slope | None = None
    rms_by_temperature: list[dict[str, Any]] = field(default_factory=list)
    check_verdicts: dict[str, int] = field(default_factory=dict)
    td_drift_ppm: Slope | None = None
    td_span_days: float = 0.0
    td_by_temperature: list[dict[str, Any]] = field(default_factory=list)
    gauge: dict[str, Any] | None = None
    triage_verdicts: dict[str, int] = field(default_factory=dict)
    fleet: dict[str, Any] | None = None
    findings: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        out = {k: v for k, v in self.__dict__.items() if not isinstance(v, Slope)}
        for name in ("rms_vs_temperature_px_per_c", "td_drift_ppm"):
            value = getattr(self, name)
            out[name] = None if value is None else value.as_json()
        return out


def _bins(temps: np.ndarray, values: np.ndarray) -> list[dict[str, Any]]:
    """Per 10 degC bin: its lower edge, n, mean and max of ``values``."""
    edges = np.floor(temps / TEMPERATURE_BIN_C) * TEMPERATURE_BIN_C
    return [
        {
            "from_c": float(e),
            "to_c": float(e + TEMPERATURE_BIN_C),
            "n": int((edges == e).sum()),
            "mean": float(values[edges == e].mean()),
            "max": float(values[edges == e].max()),
        }
        for e in np.unique(edges)
    ]


def _counts(values: list[str | None]) -> dict[str, int]:
    return {v: values.count(v) for v in sorted({v for v in values if v is not None})}


def compute_trends(serial: str, rows: list[HealthRow], fleet_rms: dict[str, tuple[float, int]]) -> Trends:
    """``serial``'s trends from its ``rows`` and the fleet's serial -> (mean check RMS px, n) (NotFoundError:
    no rows)."""
    if not rows:
        raise NotFoundError(
            f"no health reports for {serial}", "ingest some: calibctl fleet ingest REPORTS.jsonl"
        )
    by_kind: dict[str, list[HealthRow]] = {}
    for r in rows:
        by_kind.setdefault(r.kind, []).append(r)
    t = Trends(serial, {k: len(v) for k, v in sorted(by_kind.items())})
    checks = by_kind.get("check", [])
    t.check_verdicts = _counts([r.verdict for r in checks])
    warm = [r for r in checks if r.temperature_c is not None and r.rms_px is not None]
    if warm:
        temps = np.array([r.temperature_c for r in warm], dtype=float)
        rms = np.array([r.rms_px for r in warm], dtype=float)
        t.rms_vs_temperature_px_per_c = fit_slope(temps, rms)
        t.rms_by_temperature = _bins(temps, rms)
    offsets = by_kind.get("timeoffset", [])
    if offsets:
        seconds = np.array([(r.at - offsets[0].at).total_seconds() for r in offsets], dtype=float)
        td_ms = np.array([r.td_ms for r in offsets], dtype=float)
        drift = fit_slope(seconds, td_ms)  # ms per s; x 1e3 is parts per million
        t.td_drift_ppm = None if drift is None else Slope(drift.slope * 1e3, drift.sigma * 1e3, drift.n)
        t.td_span_days = float(seconds[-1] / 86400.0)
        t.td_by_temperature = _bins(np.array([r.temperature_c for r in offsets], dtype=float), td_ms)
    gauges = np.array([r.ratio for r in by_kind.get("gauge", [])], dtype=float)
    if gauges.size:
        p05, p50, p95 = np.percentile(gauges, [5, 50, 95])
        t.gauge = {"n": int(gauges.size), "median": float(p50), "p05": float(p05), "p95": float(p95)}
    t.triage_verdicts = _counts([r.verdict for r in by_kind.get("triage", [])])
    if serial in fleet_rms and len(fleet_rms) >= 2:
        means = {s: m for s, (m, _) in fleet_rms.items()}
        values = np.array(sorted(means.values()))
        others = [m for s, m in means.items() if s != serial]
        t.fleet = {
            "serials": len(means),
            "this_mean_rms_px": means[serial],
            "fleet_median_rms_px": float(np.median(values)),
            "others_median_rms_px": float(np.median(others)),
            "min_rms_px": float(values[0]),
            "max_rms_px": float(values[-1]),
            "max_over_min": float(values[-1] / values[0]) if values[0] > 0 else None,
            "rank": int(sum(m <= means[serial] for m in values)),
            "worst": max(means, key=lambda s: means[s]),
        }
    _findings(t)
    return t


def _findings(t: Trends) -> None:
    """Plain-language flags where a conditional crosses the seed's thresholds (at 2 sigma for slopes)."""
    d = t.td_drift_ppm
    if d is not None and abs(d.slope) > DRIFT_PPM and abs(d.slope) > 2 * d.sigma:
        t.findings.append(
            f"time offset drifts {d.slope:+.1f} +- {d.sigma:.1f} ppm (> {DRIFT_PPM:g} ppm): clock drift, "
            "a constant td will not hold; estimate it as a state"
        )
    s = t.rms_vs_temperature_px_per_c
    if s is not None and s.slope > 2 * s.sigma and len(t.rms_by_temperature) >= 2:
        low, high = t.rms_by_temperature[0], t.rms_by_temperature[-1]
        t.findings.append(
            f"RMS rises with temperature, {s.slope:+.4f} +- {s.sigma:.4f} px/degC: {low['mean']:.3f} px "
            f"at {low['from_c']:g}..{low['to_c']:g} degC, {high['mean']:.3f} px at "
            f"{high['from_c']:g}..{high['to_c']:g} degC (thermal)"
        )
    f = t.fleet
    if f is not None and f["max_over_min"] is not None and f["max_over_min"] > SPREAD_RATIO:
        who = "this camera" if f["worst"] == t.serial else f"camera {f['worst']}"
        t.findings.append(
            f"per-camera spread {f['max_over_min']:.1f}x (max/min mean RMS > {SPREAD_RATIO:g}): "
            f"{who} is the worst, hidden in a fleet median of {f['fleet_median_rms_px']:.3f} px"
        )
