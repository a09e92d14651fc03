"""Residual triage: which calibration parameter moved, from a buffer of reprojection residuals.

Model (seed chapters 4 and 5; residual = observed - predicted along the flow direction, px):

    residual = a + eps r + (dk1 / f^2) r^3 + (f dt) / Z + td u + t_line (u row) + noise

One joint OLS on a design matrix [1, r, r^3, 1/Z, u, u*row] after averaging every column per
keyframe (features of one keyframe share a pose, so they share an error; the keyframe is the unit of
independence). Each coefficient is one fault in its own units:

    1      -> a px: extrinsic rotation (deg = atan(a/f)) OR principal point (px); the same column,
              so the two are never told apart here
    r      -> df/f            r^3 -> k1 = coef f^2        1/Z -> lever arm m = coef / f
    u      -> time offset s    u*row -> line delay s/row

A channel names a fault when |t| >= max(t_min, t_{1-alpha/2, dof}) AND its effect (|coef| times the
99th percentile of |column| over the rows) is at least ``min_effect_px``: significant but sub-pixel
effects on huge logs are reported, not alarmed. Columns that never varied carry no information and
are dropped; columns correlated above ``collinear_corr`` are fitted as one and not attributed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calibctl.core.diagnostics.regression import (
    LinearFit,
    column_correlations,
    fit_line,
    fit_ols,
    variance_inflation,
)
from calibctl.core.diagnostics.student_t import t_quantile
from calibctl.errors import InputError

DEGENERACY_NOTE = "extrinsic rotation or principal point, these cannot be separated from this data"
GAUGE_POINTER = (
    "no residual signature: the geometry is self-consistent. If the robot is still wrong, "
    "suspect a metric gauge (board square size, wheel radius, stereo baseline): "
    "run `calibctl gauge` on a wheel/VIO odometry log"
)


@dataclass(frozen=True)
class ChannelSpec:
    key: str
    column: str
    fault: str
    unit: str
    coef_unit: str


CHANNELS = (
    ChannelSpec("rotation_or_principal_point", "1", DEGENERACY_NOTE, "deg", "px"),
    ChannelSpec("focal", "r", "focal length scale error", "df/f", "px/px"),
    ChannelSpec("k1", "r^3", "radial distortion k1 error", "k1", "px/px^3"),
    ChannelSpec("lever_arm", "1/Z", "extrinsic translation (lever arm)", "m", "px*m"),
    ChannelSpec("time_offset", "u", "camera time offset", "s", "s"),
    ChannelSpec("line_delay", "u*row", "rolling-shutter line delay", "s/row", "s/row"),
)


@dataclass(frozen=True)
class TriageConfig:
    focal_px: float = 800.0
    t_min: float = 4.0
    alpha: float = 0.001
    min_effect_px: float = 0.5
    collinear_corr: float = 0.995
    collinear_vif: float = 1000.0
    min_keyframes: int = 12
    min_speed_px_s: float = 20.0
    thermal_slope_px_per_k: float = 0.005


@dataclass
class ChannelResult:
    spec: ChannelSpec
    status: str  # "fault" | "not significant" | "below effect floor" | "no information" | "collinear"
    coef: float | None = None
    se: float | None = None
    t: float | None = None
    p_value: float | None = None
    ci: tuple[float, float] | None = None
    value: float | None = None
    value_ci: tuple[float, float] | None = None
    effect_px: float | None = None
    note: str = ""


@dataclass
class MarginalFit:
    covariate: str
    response: str
    slope_unit: str
    fit: LinearFit
    x: np.ndarray
    y: np.ndarray


@dataclass
class CameraTriage:
    camera: str
    n_rows: int
    n_keyframes: int
    keyframes_given: bool
    rms_px: float
    t_critical: float
    joint: LinearFit
    channels: list[ChannelResult]
    marginals: list[MarginalFit]
    correlations: dict[tuple[str, str], float]
    collinear: list[tuple[str, str, float]]
    radial_order: dict | None = None
    thermal: dict | None = None
    faults: list[ChannelResult] = field(default_factory=list)
    verdict: str = ""


def to_channel_units(key: str, coef: float, focal_px: float) -> float:
    """A joint-fit coefficient in the channel's own unit (see module docstring)."""
    if key == "rotation_or_principal_point":
        return math.degrees(math.atan(coef / focal_px))
    if key == "k1":
        return coef * focal_px**2
    if key == "lever_arm":
        return coef / focal_px
    return coef


def _design_columns(r, inv_z, u, row) -> dict[str, np.ndarray]:
    return {"1": np.ones_like(r), "r": r, "r^3": r**3, "1/Z": inv_z, "u": u, "u*row": u * row}


def _aggregate(keyframe, columns: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], int]:
    if keyframe is None:
        return columns, next(iter(columns.values())).size
    _, inverse = np.unique(np.asarray(keyframe), return_inverse=True)
    counts = np.bincount(inverse)
    out = {k: np.bincount(inverse, weights=v, minlength=counts.size) / counts for k, v in columns.items()}
    return out, counts.size


def _collinear_groups(names: list[str], X: np.ndarray, cfg: TriageConfig):
    corr = column_correlations(X)
    pairs = [
        (names[i], names[j], float(corr[i, j]))
        for i in range(len(names))
        for j in range(i + 1, len(names))
        if abs(corr[i, j]) >= cfg.collinear_corr
    ]
    vif = variance_inflation(X) if len(names) > 1 else np.ones(1)
    high = [names[i] for i in range(len(names)) if vif[i] >= cfg.collinear_vif]
    groups: list[list[str]] = []
    for a, b, _ in pairs:
        hit = [g for g in groups if a in g or b in g]
        merged = sorted({a, b}.union(*hit), key=names.index)
        groups = [g for g in groups if g not in hit] + [merged]
    leftover = [c for c in high if not any(c in g for g in groups)]
    if len(leftover) > 1:
        groups.append(leftover)
    corr_map = {
        (names[i], names[j]): float(corr[i, j]) for i in range(len(names)) for j in range(i + 1, len(names))
    }
    return groups, pairs, corr_map


def _p99_abs(col: np.ndarray) -> float:
    return float(np.percentile(np.abs(col), 99.0)) if col.size > 1 else float(abs(col[0]))


def _marginals(agg: dict[str, np.ndarray]) -> list[MarginalFit]:
    out = []
    for cov, resp, unit in (
        ("r", "residual_px", "px/px"),
        ("u", "residual_px", "s"),
        ("1/Z", "residual_px", "px*m"),
        ("row", "residual_over_speed_s", "s/row"),
    ):
        x, y = agg[cov], agg[resp]
        if np.ptp(x) <= 1e-12 * max(float(np.max(np.abs(x))), 1e-300):
            continue  # the covariate never varied: no information, no slope
        out.append(MarginalFit(cov, resp, unit, fit_line(x, y), x, y))
    return out


def _radial_order(agg, kept: list[str], t_crit: float) -> dict:
    names = [c for c in kept if c != "r^3"]
    names = names[:2] + ["rho^3", "rho^5"] + names[2:]
    X = np.column_stack([agg[c] for c in names])
    fit = fit_ols(X, agg["residual_px"], names)
    i3, i5 = names.index("rho^3"), names.index("rho^5")
    corr = float(column_correlations(X[:, [i3, i5]])[0, 1])
    sig3, sig5 = abs(fit.t[i3]) >= t_crit, abs(fit.t[i5]) >= t_crit
    if sig3 and not sig5:
        reading = "k1 (r^3), not k2 (r^5)"
    elif sig5 and not sig3:
        reading = "k2 (r^5), not k1 (r^3)"
    elif sig3 and sig5:
        reading = "both r^3 and r^5 terms are present"
    else:
        reading = (
            f"radial residual present but its order cannot be attributed over this radius coverage "
            f"(corr(rho^3, rho^5) = {corr:.4f})"
        )
    return {
        "b3_px_at_rmax": float(fit.coef[i3]),
        "se3": float(fit.se[i3]),
        "t3": float(fit.t[i3]),
        "b5_px_at_rmax": float(fit.coef[i5]),
        "se5": float(fit.se[i5]),
        "t5": float(fit.t[i5]),
        "corr": corr,
        "dof": fit.dof,
        "reading": reading,
    }


def _thermal(residual, keyframe, temperature, t_crit: float, cfg: TriageConfig) -> dict | None:
    kf = np.arange(residual.size) if keyframe is None else np.asarray(keyframe)
    _, inverse = np.unique(kf, return_inverse=True)
    counts = np.bincount(inverse)
    rms = np.sqrt(np.bincount(inverse, weights=residual**2) / counts)
    temp = np.bincount(inverse, weights=temperature) / counts
    if counts.size < 3 or np.ptp(temp) == 0:
        return {"status": "no information", "note": "temperature never varied"}
    fit = fit_line(temp, rms)
    slope, t = float(fit.coef[1]), float(fit.t[1])
    found = abs(t) >= t_crit and abs(slope) > cfg.thermal_slope_px_per_k
    return {
        "status": "fault" if found else "not significant",
        "slope_px_per_k": slope,
        "se": float(fit.se[1]),
        "t": t,
        "ci": [float(v) for v in fit.interval()[1]],
        "dof": fit.dof,
        "threshold_px_per_k": cfg.thermal_slope_px_per_k,
    }


def triage_camera(
    residual_px,
    radius_px,
    image_speed_px_s,
    inv_range_per_m,
    row,
    keyframe=None,
    temperature_c=None,
    camera: str = "all",
    cfg: TriageConfig = TriageConfig(),
) -> CameraTriage:
    """Triage one camera's residuals. Every array is (n,) float64 (keyframe: (n,) labels or None)."""
    y = np.asarray(residual_px, dtype=np.float64)
    r = np.asarray(radius_px, dtype=np.float64)
    u = np.asarray(image_speed_px_s, dtype=np.float64)
    inv_z = np.asarray(inv_range_per_m, dtype=np.float64)
    rows = np.asarray(row, dtype=np.float64)
    cols = _design_columns(r, inv_z, u, rows)
    r_max = float(np.max(r)) if r.size else 1.0
    raw = dict(
        cols,
        residual_px=y,
        row=rows,
        residual_over_speed_s=y / np.maximum(u, cfg.min_speed_px_s),
        **{"rho^3": (r / r_max) ** 3, "rho^5": (r / r_max) ** 5},
    )
    agg, n_kf = _aggregate(keyframe, raw)
    unit = "keyframes" if keyframe is not None else "rows"
    if n_kf < cfg.min_keyframes:
        raise InputError(
            f"camera {camera}: {n_kf} {unit}; the joint fit of {len(CHANNELS)} columns needs at "
            f"least {cfg.min_keyframes}",
            hint="log more keyframes before triaging, or triage the other cameras with --camera",
        )
    informative = [
        c.column
        for c in CHANNELS[1:]
        if np.std(agg[c.column]) > 1e-9 * max(float(np.sqrt(np.mean(agg[c.column] ** 2))), 1e-300)
    ]
    X_all = np.column_stack([agg[c] for c in informative]) if informative else np.zeros((n_kf, 0))
    groups, pairs, corr_map = _collinear_groups(informative, X_all, cfg) if informative else ([], [], {})
    dropped = {c: g[0] for g in groups for c in g[1:]}
    kept = ["1"] + [c for c in informative if c not in dropped]
    joint = fit_ols(np.column_stack([agg[c] for c in kept]), agg["residual_px"], kept)
    t_crit = max(cfg.t_min, t_quantile(1.0 - cfg.alpha / 2.0, joint.dof))
    ci = joint.interval()
    channels: list[ChannelResult] = []
    for spec in CHANNELS:
        if spec.column not in informative and spec.column != "1":
            what = "row" if spec.column == "u*row" else spec.column
            channels.append(ChannelResult(spec, "no information", note=f"{what} never varied in this data"))
            continue
        if spec.column in dropped:
            rep = dropped[spec.column]
            channels.append(
                ChannelResult(spec, "collinear", note=f"fitted together with {rep}: cannot be told apart")
            )
            continue
        i = kept.index(spec.column)
        coef, se, t = float(joint.coef[i]), float(joint.se[i]), float(joint.t[i])
        effect = abs(coef) * (1.0 if spec.column == "1" else _p99_abs(cols[spec.column]))
        group = next((g for g in groups if g[0] == spec.column), None)
        significant = abs(t) >= t_crit
        status = (
            "fault"
            if significant and effect >= cfg.min_effect_px
            else ("below effect floor" if significant else "not significant")
        )
        res = ChannelResult(
            spec,
            status,
            coef,
            se,
            t,
            float(joint.p_value[i]),
            (float(ci[i, 0]), float(ci[i, 1])),
            effect_px=effect,
        )
        if group:
            corr_txt = ", ".join(
                f"corr({a}, {b}) = {c:+.4f}" for a, b, c in pairs if a in group and b in group
            )
            res.note = (
                f"columns {', '.join(group)} are collinear "
                f"({corr_txt or 'VIF >= ' + str(cfg.collinear_vif)}): refusing to attribute"
            )
        else:
            res.value = to_channel_units(spec.key, coef, cfg.focal_px)
            lo, hi = sorted(to_channel_units(spec.key, float(v), cfg.focal_px) for v in ci[i])
            res.value_ci = (lo, hi)
        channels.append(res)
    out = CameraTriage(
        camera,
        int(y.size),
        n_kf,
        keyframe is not None,
        float(np.sqrt(np.mean(y**2))),
        t_crit,
        joint,
        channels,
        _marginals(agg),
        corr_map,
        pairs,
    )
    out.faults = sorted((c for c in channels if c.status == "fault"), key=lambda c: -abs(c.t or 0.0))
    k1 = next(c for c in channels if c.spec.key == "k1")
    if k1.status == "fault" and not k1.note and "r^3" in kept:
        out.radial_order = _radial_order(agg, kept, t_crit)
    if temperature_c is not None:
        out.thermal = _thermal(y, keyframe, np.asarray(temperature_c, dtype=np.float64), t_crit, cfg)
    out.verdict = _verdict(out)
    return out


def _verdict(tri: CameraTriage) -> str:
    parts = []
    for c in tri.faults:
        if c.note:
            parts.append(f"a residual that varies with {c.spec.column} ({c.note})")
        else:
            parts.append(c.spec.fault)
    if tri.thermal and tri.thermal.get("status") == "fault":
        parts.append("thermal drift (RMS grows with temperature)")
    if not parts:
        return GAUGE_POINTER
    return "fault: " + "; ".join(parts)


@dataclass
class TriageSummary:
    cameras: list[CameraTriage]
    camera_rms_ratio: float | None  # max/min per-camera RMS; None with one camera
    camera_rms_level: str  # "ok" | "warn" (> 1.5) | "alarm" (> 2.0) | "n/a"
    fail: bool  # a fault was named or the camera spread alarmed: exit 1


CAMERA_RMS_WARN = 1.5
CAMERA_RMS_ALARM = 2.0


def triage_by_camera(
    residual_px,
    radius_px,
    image_speed_px_s,
    inv_range_per_m,
    row,
    camera=None,
    keyframe=None,
    temperature_c=None,
    cfg: TriageConfig = TriageConfig(),
) -> TriageSummary:
    """Split the buffer per camera (calibration faults are per camera), triage each, compare their RMS."""
    arrays = [np.asarray(a) for a in (residual_px, radius_px, image_speed_px_s, inv_range_per_m, row)]
    extra = [None if a is None else np.asarray(a) for a in (keyframe, temperature_c)]
    if camera is None:
        names, masks = ["all"], [np.ones(arrays[0].size, dtype=bool)]
    else:
        cam = np.asarray(camera).astype(str)
        names = [str(c) for c in np.unique(cam)]
        masks = [cam == c for c in names]
    results = []
    for name, mask in zip(names, masks, strict=True):
        res, rad, speed, inv_z, rows = (a[mask] for a in arrays)
        kf, temp = (None if a is None else a[mask] for a in extra)
        results.append(
            triage_camera(res, rad, speed, inv_z, rows, keyframe=kf, temperature_c=temp, camera=name, cfg=cfg)
        )
    ratio, level = None, "n/a"
    if len(results) > 1:
        rms = [c.rms_px for c in results]
        ratio = max(rms) / min(rms) if min(rms) > 0 else math.inf
        level = "alarm" if ratio > CAMERA_RMS_ALARM else "warn" if ratio > CAMERA_RMS_WARN else "ok"
    fail = level == "alarm" or any(c.faults or (c.thermal or {}).get("status") == "fault" for c in results)
    return TriageSummary(results, ratio, level, fail)
