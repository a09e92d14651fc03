"""Field diagnostics use cases: triage, gauge, timeoffset, synth-residuals.

Each ``run_*`` reads and validates its files (diagnostics_io), calls the pure core
(calibctl.core.diagnostics), optionally writes PNG plots (diagnostics_plots) and returns a plain
JSON-ready dict. The dicts are the documented ``--json`` contract (docs/diagnostics.md); every one
carries ``schema`` and ``verdict`` ("pass", "fail" or "refused"; fail and refused exit 1).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from calibctl.core.diagnostics import faults
from calibctl.core.diagnostics.gauge import ALARM_BAND, WARN_BAND, gauge_ratio, steps_from_cumulative
from calibctl.core.diagnostics.timeoffset import (
    OffsetConfig,
    OffsetEstimate,
    estimate_drift,
    estimate_time_offset,
)
from calibctl.core.diagnostics.triage import (
    CAMERA_RMS_ALARM,
    CAMERA_RMS_WARN,
    CameraTriage,
    ChannelResult,
    TriageConfig,
    TriageSummary,
    triage_by_camera,
)
from calibctl.errors import AlreadyExistsError, InputError, NotFoundError, UsageError
from calibctl.workflows.diagnostics import diagnostics_io as dio

# diagnostics_plots (matplotlib, about 0.3 s to import) is imported inside the run_* functions, only
# when a plot is drawn.

DEFAULT_FOCAL_PX = 800.0
RESIDUAL_COLUMNS = ("residual_px", "radius_px", "image_speed_px_s", "inv_range_per_m", "row")
ODOMETRY_COLUMNS = ("t_s", "wheel_distance_m", "vio_distance_m")
RATE_COLUMNS = ("t_s", "rate_rad_s")
DRIFT_PPM_SIGNIFICANT = 5.0


def num(value: Any) -> float | None:
    """A JSON-safe float: None for None, NaN and infinities."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _pair(values) -> list[float | None] | None:
    return None if values is None else [num(v) for v in values]


def channel_dict(c: ChannelResult) -> dict[str, Any]:
    out = {
        "key": c.spec.key,
        "fault": c.spec.fault,
        "column": c.spec.column,
        "status": c.status,
        "coef": num(c.coef),
        "coef_unit": c.spec.coef_unit,
        "se": num(c.se),
        "t": num(c.t),
        "p_value": num(c.p_value),
        "ci95": _pair(c.ci),
        "value": num(c.value),
        "value_unit": c.spec.unit,
        "value_ci95": _pair(c.value_ci),
        "effect_px": num(c.effect_px),
        "note": c.note,
    }
    if c.spec.key == "rotation_or_principal_point":
        out["principal_point_px"] = num(c.coef) if not c.note else None
        out["principal_point_ci95_px"] = _pair(c.ci) if not c.note else None
    return out


def camera_dict(cam: CameraTriage) -> dict[str, Any]:
    joint = cam.joint
    return {
        "camera": cam.camera,
        "n_rows": cam.n_rows,
        "n_keyframes": cam.n_keyframes,
        "aggregation": "keyframe means"
        if cam.keyframes_given
        else "none: no keyframe column, rows treated as independent",
        "rms_px": cam.rms_px,
        "dof": joint.dof,
        "sigma_px": joint.sigma,
        "t_critical": cam.t_critical,
        "verdict": cam.verdict,
        "faults": [c.spec.key for c in cam.faults],
        "channels": [channel_dict(c) for c in cam.channels],
        "marginal": [
            {
                "covariate": m.covariate,
                "response": m.response,
                "intercept": num(m.fit.coef[0]),
                "slope": num(m.fit.coef[1]),
                "slope_unit": m.slope_unit,
                "se": num(m.fit.se[1]),
                "t": num(m.fit.t[1]),
                "ci95": _pair(m.fit.interval()[1]),
                "n": m.fit.n,
            }
            for m in cam.marginals
        ],
        "correlations": [{"a": a, "b": b, "corr": num(v)} for (a, b), v in cam.correlations.items()],
        "collinear": [{"a": a, "b": b, "corr": num(v)} for a, b, v in cam.collinear],
        "radial_order": cam.radial_order,
        "thermal": cam.thermal,
    }


def triage_dict(summary: TriageSummary, cfg: TriageConfig) -> dict[str, Any]:
    return {
        "schema": "calibctl.diagnostics.triage/1",
        "verdict": "fail" if summary.fail else "pass",
        "focal_px": cfg.focal_px,
        "settings": {
            "t_min": cfg.t_min,
            "alpha": cfg.alpha,
            "min_effect_px": cfg.min_effect_px,
            "collinear_corr": cfg.collinear_corr,
            "collinear_vif": cfg.collinear_vif,
            "min_keyframes": cfg.min_keyframes,
        },
        "cameras": [camera_dict(c) for c in summary.cameras],
        "camera_rms": {
            "per_camera": {c.camera: c.rms_px for c in summary.cameras},
            "max_over_min": num(summary.camera_rms_ratio),
            "level": summary.camera_rms_level,
        },
    }


def run_triage(
    path: Path,
    focal_px: float | None = None,
    camera: str | None = None,
    t_min: float = 4.0,
    min_effect_px: float = 0.5,
    plot_dir: Path | None = None,
) -> dict[str, Any]:
    table = dio.read_table(
        path,
        RESIDUAL_COLUMNS,
        ("temperature_c",),
        ("camera",),
        what="residual buffer",
        optional_labels=("keyframe",),
    )
    for col in ("radius_px", "image_speed_px_s", "inv_range_per_m", "row"):
        dio.require_nonnegative(table, col)
    cams = table.text.get("camera")
    mask = np.ones(table.n_rows, dtype=bool)
    if camera is not None:
        if cams is None:
            raise UsageError(f"--camera {camera} given but {table.path.name} has no camera column")
        mask = cams == camera
        if not mask.any():
            raise NotFoundError(
                f"camera {camera!r} is not in {table.path.name}",
                hint=f"cameras present: {', '.join(sorted(set(cams.tolist())))}",
            )
    cfg = TriageConfig(focal_px=focal_px or DEFAULT_FOCAL_PX, t_min=t_min, min_effect_px=min_effect_px)
    kf = table.labels.get("keyframe")
    temp = table.numeric.get("temperature_c")
    res, rad, speed, inv_z, rows = (table.numeric[c][mask] for c in RESIDUAL_COLUMNS)
    summary = triage_by_camera(
        res,
        rad,
        speed,
        inv_z,
        rows,
        camera=None if cams is None else cams[mask],
        keyframe=None if kf is None else kf[mask],
        temperature_c=None if temp is None else temp[mask],
        cfg=cfg,
    )
    out = triage_dict(summary, cfg)
    out["input"] = str(path)
    out["focal_px_source"] = "option" if focal_px else "default (the seed bench's 800 px; pass --focal-px)"
    out["camera_rms"].update(warn_above=CAMERA_RMS_WARN, alarm_above=CAMERA_RMS_ALARM)
    if plot_dir:
        from calibctl.workflows.diagnostics import diagnostics_plots as plots  # matplotlib: only when drawing

        out["plots"] = [str(p) for p in plots.plot_triage(summary, plots.prepare_plot_dir(plot_dir))]
    else:
        out["plots"] = []
    return out


def _odometry_steps(table: dio.Table, distances: str) -> tuple[np.ndarray, np.ndarray, str]:
    wheel, vio = table.numeric["wheel_distance_m"], table.numeric["vio_distance_m"]
    monotone = bool(np.all(np.diff(wheel) >= 0) and np.all(np.diff(vio) >= 0))
    if distances == "auto":
        distances = "cumulative" if monotone and wheel[-1] > wheel[0] and vio[-1] > vio[0] else "per-sample"
        source = f"{distances} (auto-detected; pass --distances to override)"
    else:
        source = f"{distances} (option)"
    if distances == "cumulative":
        for name, col in (("wheel_distance_m", wheel), ("vio_distance_m", vio)):
            bad = np.flatnonzero(np.diff(col) < 0)
            if bad.size:
                raise InputError(
                    f"{table.path.name}: cumulative {name} decreases at line {int(table.lines[bad[0] + 1])}",
                    hint="if these are per-sample distances pass --distances per-sample",
                )
        return steps_from_cumulative(wheel), steps_from_cumulative(vio), source
    for name in ("wheel_distance_m", "vio_distance_m"):
        dio.require_nonnegative(table, name)
    return wheel, vio, source


def run_gauge(
    path: Path,
    window_s: float = 60.0,
    distances: str = "auto",
    min_step_m: float = 1e-4,
    plot_dir: Path | None = None,
) -> dict[str, Any]:
    if distances not in ("auto", "cumulative", "per-sample"):
        raise UsageError(f"--distances must be auto, cumulative or per-sample, not {distances!r}")
    table = dio.read_table(path, ODOMETRY_COLUMNS, what="odometry log")
    dio.require_min_rows(table, 2, "a distance ratio")
    dio.require_increasing(table, "t_s")
    wheel, vio, source = _odometry_steps(table, distances)
    t = table.numeric["t_s"]
    rep = gauge_ratio(t, wheel, vio, window_s=window_s, min_step_m=min_step_m)
    out = {
        "schema": "calibctl.diagnostics.gauge/1",
        "input": str(path),
        "distances": source,
        "window_s": window_s,
        "warn_band": list(WARN_BAND),
        "alarm_band": list(ALARM_BAND),
        "verdict": "fail" if rep.level == "alarm" else "pass",
        "level": rep.level,
        "first_alarm_s": num(rep.first_alarm_s),
        "median_ratio": rep.median_of_windows,
        "spread_between_windows": rep.spread_of_windows,
        "median_spread_within_window": rep.median_spread,
        "diagnosis": rep.diagnosis,
        "tail_unused_s": rep.tail_unused_s,
        "stationary_samples": rep.n_stationary,
        "windows": [
            {
                "start_s": w.start_s,
                "end_s": w.end_s,
                "n_samples": w.n_samples,
                "median_ratio": num(w.median_ratio),
                "spread": num(w.spread),
                "mean_ratio": num(w.mean_ratio),
                "frac_above_one": num(w.frac_above_one),
                "level": w.level,
            }
            for w in rep.windows
        ],
        "plots": [],
    }
    if plot_dir:
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(vio >= min_step_m, wheel / np.where(vio >= min_step_m, vio, 1.0), np.nan)
        from calibctl.workflows.diagnostics import diagnostics_plots as plots  # matplotlib: only when drawing

        out["plots"] = [str(p) for p in plots.plot_gauge(rep, t, ratio, plots.prepare_plot_dir(plot_dir))]
    return out


def _read_rate_log(path: Path, what: str) -> dio.Table:
    table = dio.read_table(path, RATE_COLUMNS, what=what)
    dio.require_min_rows(table, 10, "a time-offset estimate")
    dio.require_increasing(table, "t_s")
    return table


def _offset_dict(est: OffsetEstimate) -> dict[str, Any]:
    return {
        "td_s": num(est.td_s),
        "td_ms": num(None if est.td_s is None else est.td_s * 1e3),
        "sigma_s": num(est.sigma_s),
        "ci95_s": None if est.ci_s is None else [num(v) for v in est.ci_s],
        "refused": est.refused,
        "rate_hz": est.rate_hz,
        "overlap_s": list(est.overlap_s),
        "n_samples": est.n_samples,
        "rate_std_rad_s": est.rate_std,
        "peak_ncc": num(est.peak_ncc),
        "integer_lag": est.integer_lag,
        "subsample": num(est.subsample),
        "jackknife_blocks": est.n_blocks,
    }


def run_timeoffset(
    gyro_path: Path,
    camera_path: Path,
    rate_hz: float | None = None,
    max_lag_s: float = 0.2,
    max_sigma_ms: float = 2.0,
    window_s: float | None = None,
    plot_dir: Path | None = None,
) -> dict[str, Any]:
    gyro = _read_rate_log(gyro_path, "gyro log")
    cam = _read_rate_log(camera_path, "camera rate log")
    cfg = OffsetConfig(rate_hz=rate_hz, max_lag_s=max_lag_s, max_sigma_s=max_sigma_ms * 1e-3)
    logs = (gyro.numeric["t_s"], gyro.numeric["rate_rad_s"], cam.numeric["t_s"], cam.numeric["rate_rad_s"])
    drift = estimate_drift(*logs, window_s=window_s, cfg=cfg) if window_s else None
    est = estimate_time_offset(*logs, cfg=cfg)
    out: dict[str, Any] = {
        "schema": "calibctl.diagnostics.timeoffset/1",
        "gyro": str(gyro_path),
        "camera": str(camera_path),
        "sign_convention": "t_gyro = t_camera + td: add td to camera timestamps; positive td = camera "
        "stamps early",
        **_offset_dict(est),
        "correlation": {"lags_s": [float(v) for v in est.lags_s], "ncc": [float(v) for v in est.ncc]},
        "drift": None,
        "plots": [],
    }
    refused = est.refused
    if drift is not None:
        significant = (
            drift.drift_ppm is not None
            and drift.ci_ppm is not None
            and abs(drift.drift_ppm) > DRIFT_PPM_SIGNIFICANT
            and not drift.ci_ppm[0] <= 0.0 <= drift.ci_ppm[1]
        )
        out["drift"] = {
            "window_s": window_s,
            "drift_ppm": num(drift.drift_ppm),
            "se_ppm": num(drift.se_ppm),
            "ci95_ppm": None if drift.ci_ppm is None else list(drift.ci_ppm),
            "dof": None if drift.fit is None else drift.fit.dof,
            "refused": drift.refused,
            "td_at_t0_s": None if drift.fit is None else num(drift.fit.coef[0]),
            "reading": (
                drift.refused
                or (
                    "clock drift, not a constant offset: estimate td online or fix the clocks"
                    if significant
                    else f"no drift above {DRIFT_PPM_SIGNIFICANT:g} ppm"
                )
            ),
            "windows": [
                {"t_mid_s": tm, "td_s": num(e.td_s), "sigma_s": num(e.sigma_s), "refused": e.refused}
                for tm, e in drift.windows
            ],
        }
        refused = refused or (f"drift: {drift.refused}" if drift.refused else None)
    out["verdict"] = "refused" if refused else "pass"
    out["reason"] = refused
    if plot_dir:
        from calibctl.workflows.diagnostics import diagnostics_plots as plots  # matplotlib: only when drawing

        out["plots"] = [str(p) for p in plots.plot_timeoffset(est, drift, plots.prepare_plot_dir(plot_dir))]
    return out


def sibling_paths(out_path: Path) -> dict[str, Path]:
    stem, parent = out_path.stem, out_path.parent
    return {
        "residuals": out_path,
        "odometry": parent / f"{stem}_odometry.csv",
        "gyro": parent / f"{stem}_gyro.csv",
        "camera": parent / f"{stem}_camera.csv",
    }


MAX_SYNTH_ROWS = 5_000_000  # per file (~250 MB of CSV); --keyframes 10000000 grew to 21 GiB and was killed
SYNTH_RATES_HZ = {"odometry": 50.0, "gyro": 200.0}  # the generators' sample rates (faults.synth_*)


def check_synth_size(
    magnitude: float,
    noise_px: float,
    keyframes: int,
    features: int,
    cameras: int,
    slip: float,
    odometry_s: float,
    rate_log_s: float,
    drift_ppm: float,
) -> None:
    """UsageError (exit 2) naming the limit, before anything is generated: every number finite, every
    file at most ``MAX_SYNTH_ROWS`` rows."""
    numbers = {
        "--magnitude": magnitude,
        "--noise-px": noise_px,
        "--slip": slip,
        "--odometry-s": odometry_s,
        "--rate-log-s": rate_log_s,
        "--drift-ppm": drift_ppm,
    }
    bad = [f"{k} {v!r}" for k, v in numbers.items() if not (math.isfinite(v) and abs(v) <= 1e9)]
    if bad:
        raise UsageError(f"not a usable number: {', '.join(bad)}", "give finite values")
    for name, value in {"--keyframes": keyframes, "--features": features, "--cameras": cameras}.items():
        if value < 1:
            raise UsageError(f"{name} must be 1 or more, got {value}")
    sizes = {
        "residual rows (--keyframes x --features x --cameras)": keyframes * features * cameras,
        "odometry rows (--odometry-s x 50 Hz)": odometry_s * SYNTH_RATES_HZ["odometry"],
        "gyro rows (--rate-log-s x 200 Hz)": rate_log_s * SYNTH_RATES_HZ["gyro"],
    }
    for what, rows in sizes.items():
        if rows > MAX_SYNTH_ROWS:
            raise UsageError(
                f"{what}: {rows:.0f} is over the limit of {MAX_SYNTH_ROWS} rows per file",
                "a synthetic buffer of a few hundred thousand rows shows every fault",
            )


def run_synth(
    out_path: Path,
    fault: str,
    magnitude: float | None = None,
    noise_px: float = 0.3,
    seed: int = 0,
    keyframes: int = 500,
    features: int = 80,
    cameras: int = 1,
    slip: float = 0.01,
    odometry_s: float = 600.0,
    rate_log_s: float = 20.0,
    drift_ppm: float = 0.0,
    force: bool = False,
) -> dict[str, Any]:
    if fault not in faults.FAULTS:
        raise UsageError(f"unknown fault {fault!r}", hint=f"choose one of {', '.join(faults.FAULTS)}")
    mag = faults.DEFAULT_MAGNITUDE[fault] if magnitude is None else magnitude
    check_synth_size(mag, noise_px, keyframes, features, cameras, slip, odometry_s, rate_log_s, drift_ppm)
    if fault == "gauge" and mag <= 0:
        raise UsageError(
            "a gauge magnitude is a believed/true scale factor and must be positive (0.92 = 23/25 mm)"
        )
    paths = sibling_paths(Path(out_path))
    clash = [str(p) for p in paths.values() if p.exists()]
    if clash and not force:
        raise AlreadyExistsError(f"{', '.join(clash)} already exist(s)", hint="pass --force to overwrite")
    buf = faults.synth_residual_buffer(fault, mag, noise_px, seed, keyframes, features, n_cameras=cameras)
    odo = faults.synth_odometry(
        gauge_scale=mag if fault == "gauge" else 1.0, slip_std=slip, duration_s=odometry_s, seed=seed
    )
    gyro, cam = faults.synth_rate_logs(
        td_s=mag if fault == "time-offset" else 0.0,
        duration_s=rate_log_s,
        gyro_hz=200.0,
        camera_hz=30.0,
        noise_frac=0.02,
        drift_ppm=drift_ppm,
        seed=seed,
    )
    odo_cum = {
        "t_s": odo["t_s"],
        "wheel_distance_m": np.cumsum(odo["wheel_distance_m"]),
        "vio_distance_m": np.cumsum(odo["vio_distance_m"]),
    }
    for key, cols in (("residuals", buf), ("odometry", odo_cum), ("gyro", gyro), ("camera", cam)):
        dio.write_table(paths[key], cols, force=True)
    return {
        "schema": "calibctl.diagnostics.synth/1",
        "verdict": "pass",
        "fault": fault,
        "magnitude": mag,
        "magnitude_unit": faults.MAGNITUDE_UNIT[fault],
        "noise_px": noise_px,
        "seed": seed,
        "rows": int(buf["residual_px"].size),
        "keyframes": keyframes,
        "cameras": cameras,
        "faulty_camera": "cam0",
        "files": {k: str(p) for k, p in paths.items()},
        "odometry": {
            "duration_s": odometry_s,
            "slip_std": slip,
            "vio_scale": mag if fault == "gauge" else 1.0,
            "format": "cumulative",
        },
        "rate_logs": {
            "duration_s": rate_log_s,
            "gyro_hz": 200.0,
            "camera_hz": 30.0,
            "td_s": mag if fault == "time-offset" else 0.0,
            "drift_ppm": drift_ppm,
        },
    }
