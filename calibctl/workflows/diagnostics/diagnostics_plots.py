"""PNG plots a field technician opens: one figure per question, the answer drawn on it.

Matplotlib through the Agg canvas only (no pyplot, no display, no global state), so plotting works
on a headless station and from several threads.
"""

from __future__ import annotations

import io
import re
import textwrap
from pathlib import Path

import numpy as np

from calibctl.core.diagnostics.gauge import ALARM_BAND, WARN_BAND, GaugeReport
from calibctl.core.diagnostics.timeoffset import DriftEstimate, OffsetEstimate
from calibctl.core.diagnostics.triage import CameraTriage, TriageSummary
from calibctl.errors import InputError, MissingExtraError
from calibctl.files import file_errors, write_atomic

try:  # matplotlib is the optional calibctl[plots]; this module is imported only to draw
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
except ModuleNotFoundError as exc:
    raise MissingExtraError("plots", "--plot", exc.name) from exc

_LABELS = {
    "r": ("radius from principal point r [px]", "residual [px]"),
    "u": ("image speed u [px/s]", "residual [px]"),
    "1/Z": ("inverse range 1/Z [1/m]", "residual [px]"),
    "row": ("sensor row", "residual / image speed [s]"),
}
_MARKS = {
    "fault": "#c0392b",
    "below effect floor": "#e67e22",
    "not significant": "#7f8c8d",
    "collinear": "#8e44ad",
}


def prepare_plot_dir(plot_dir: Path) -> Path:
    plot_dir = Path(plot_dir)
    if plot_dir.exists() and not plot_dir.is_dir():
        raise InputError(f"--plot {plot_dir} exists and is not a directory")
    with file_errors("create the plot folder", plot_dir):
        plot_dir.mkdir(parents=True, exist_ok=True)
    return plot_dir


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=110)
    return write_atomic(path, png.getvalue(), force=True)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name) or "camera"


def _marginal_panel(ax, m) -> None:
    a, b = m.fit.coef
    ci = m.fit.interval()[1]
    ax.scatter(m.x, m.y, s=6, alpha=0.45, color="#2c3e50", label="keyframe means")
    xs = np.linspace(float(m.x.min()), float(m.x.max()), 50)
    ax.plot(xs, a + b * xs, color="#c0392b", lw=2, label="fit (with intercept)")
    ax.axhline(0.0, color="0.6", lw=0.8)
    xl, yl = _LABELS[m.covariate]
    ax.set_xlabel(xl)
    ax.set_ylabel(yl)
    ax.set_title(
        f"slope {b:.4g} {m.slope_unit}  [{ci[0]:.3g}, {ci[1]:.3g}]  t = {m.fit.t[1]:.1f}", fontsize=9
    )
    ax.legend(fontsize=7, loc="best")


def plot_triage(summary: TriageSummary, plot_dir: Path) -> list[Path]:
    """triage_<camera>.png per camera: residual against each covariate with its fit line, and the
    joint fit's |t| per channel against the naming threshold."""
    out = []
    for cam in summary.cameras:
        fig = Figure(figsize=(15, 8.5), layout="constrained")
        axes = fig.subplots(2, 3).ravel()
        by_cov = {m.covariate: m for m in cam.marginals}
        for ax, cov in zip(axes[:4], ("r", "u", "1/Z", "row"), strict=True):
            if cov in by_cov:
                _marginal_panel(ax, by_cov[cov])
            else:
                ax.text(0.5, 0.5, f"{cov}: never varied\n(no information)", ha="center", va="center")
                ax.set_axis_off()
        _joint_panel(axes[4], cam)
        _camera_panel(axes[5], summary)
        fig.suptitle(f"calibctl triage - camera {cam.camera}: {cam.verdict[:110]}", fontsize=10)
        out.append(_save(fig, plot_dir / f"triage_{_safe(cam.camera)}.png"))
    return out


def _joint_panel(ax, cam: CameraTriage) -> None:
    chans = [(c, float(c.t)) for c in cam.channels if c.t is not None]
    names = [c.spec.key.replace("_", " ") for c, _ in chans]
    ts = [abs(t) if np.isfinite(t) else 1e6 for _, t in chans]
    ax.barh(names, ts, color=[_MARKS.get(c.status, "#7f8c8d") for c, _ in chans])
    ax.axvline(cam.t_critical, color="k", ls="--", lw=1, label=f"naming threshold |t| = {cam.t_critical:.2f}")
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlabel("|t| in the joint fit (red: fault named)")
    ax.set_title("joint fit: 1, r, r^3, 1/Z, u, u*row", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")


def _camera_panel(ax, summary: TriageSummary) -> None:
    if len(summary.cameras) < 2:
        ax.text(0.5, 0.5, "one camera:\nno per-camera RMS comparison", ha="center", va="center")
        ax.set_axis_off()
        return
    names = [c.camera for c in summary.cameras]
    rms = [c.rms_px for c in summary.cameras]
    ax.bar(names, rms, color="#2c3e50")
    ax.axhline(2.0 * min(rms), color="#c0392b", ls="--", lw=1, label="alarm: 2x the best camera")
    ax.axhline(1.5 * min(rms), color="#e67e22", ls=":", lw=1, label="warn: 1.5x")
    ax.set_ylabel("RMS residual [px]")
    ax.set_title(
        f"per-camera RMS, max/min = {summary.camera_rms_ratio:.2f} ({summary.camera_rms_level})", fontsize=9
    )
    ax.legend(fontsize=7)


def plot_gauge(report: GaugeReport, t_s: np.ndarray, ratio: np.ndarray, plot_dir: Path) -> list[Path]:
    """gauge.png: window medians with per-window spread over time, inside the warn and alarm bands."""
    fig = Figure(figsize=(11, 7))
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    for ax in (top, bottom):
        ax.axhspan(ALARM_BAND[0], ALARM_BAND[1], color="#f9e79f", alpha=0.5, label="warn band 0.98-1.02")
        ax.axhspan(WARN_BAND[0], WARN_BAND[1], color="#abebc6", alpha=0.7, label="ok 0.99-1.01")
        ax.axhline(1.0, color="0.4", lw=0.8)
    scored = [w for w in report.windows if w.median_ratio is not None]
    mid = np.array([0.5 * (w.start_s + w.end_s) for w in scored])
    med = np.array([w.median_ratio for w in scored])
    spread = np.array([w.spread for w in scored])
    colors = {"ok": "#1e8449", "warn": "#d68910", "alarm": "#c0392b"}
    top.errorbar(
        mid, med, yerr=spread, fmt="none", ecolor="0.3", capsize=3, label="per-sample spread (robust sigma)"
    )
    top.scatter(
        mid, med, c=[colors[w.level] for w in scored], s=40, zorder=3, label=f"{report.window_s:g} s median"
    )
    lo, hi = min(0.97, float(np.min(med - spread))), max(1.03, float(np.max(med + spread)))
    top.set_ylim(lo - 0.005, hi + 0.005)
    top.set_ylabel("wheel / VIO distance")
    top.set_title(
        textwrap.fill(f"metric gauge: {report.level.upper()} - {report.diagnosis}", 140), fontsize=8
    )
    top.legend(fontsize=7, loc="best")
    step = max(1, t_s.size // 20000)
    bottom.scatter(t_s[::step], ratio[::step], s=1, alpha=0.25, color="#2c3e50")
    bottom.set_ylim(lo - 0.02, hi + 0.02)
    bottom.set_xlabel("time [s]")
    bottom.set_ylabel("per-sample ratio")
    fig.tight_layout()
    return [_save(fig, plot_dir / "gauge.png")]


def _zoom_panel(ax, est: OffsetEstimate, td_ms: float) -> None:
    k = int(np.argmax(est.ncc))
    lo, hi = max(0, k - 4), min(est.ncc.size, k + 5)
    ms = est.lags_s * 1e3
    ax.plot(ms[lo:hi], est.ncc[lo:hi], "o", color="#2c3e50", label="NCC at integer lags")
    y0, y1, y2 = est.ncc[k - 1], est.ncc[k], est.ncc[k + 1]
    a, b = (y0 - 2 * y1 + y2) / 2.0, (y2 - y0) / 2.0
    d = np.linspace(-1.5, 1.5, 60)
    step_ms = 1e3 / est.rate_hz
    ax.plot(ms[k] + d * step_ms, a * d**2 + b * d + y1, color="#c0392b", label="parabola through the top 3")
    ax.axvline(ms[k], color="0.5", ls=":", label=f"integer peak {ms[k]:.1f} ms")
    ax.axvline(td_ms, color="#c0392b", lw=2, label=f"vertex {td_ms:.3f} ms")
    ax.set_xlabel("td [ms]")
    ax.set_title(f"sub-sample refinement: delta = {(td_ms - ms[k]) / step_ms:+.3f} samples", fontsize=9)
    ax.legend(fontsize=7)


def plot_timeoffset(est: OffsetEstimate, drift: DriftEstimate | None, plot_dir: Path) -> list[Path]:
    """timeoffset.png: the correlation curve with its refined peak; timeoffset_drift.png with --window."""
    out = []
    fig = Figure(figsize=(13, 5))
    ax, zoom = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3, 2]})
    if est.ncc.size:
        ax.plot(est.lags_s * 1e3, est.ncc, "o-", ms=3, color="#2c3e50", label="normalised cross-correlation")
    if est.td_s is not None and est.sigma_s is not None:
        ax.axvline(
            est.td_s * 1e3,
            color="#c0392b",
            lw=2,
            label=f"td = {est.td_s * 1e3:.3f} +/- {est.sigma_s * 1e3:.3f} ms (parabolic peak)",
        )
        _zoom_panel(zoom, est, est.td_s * 1e3)
    else:
        zoom.set_axis_off()
    ax.set_xlabel("td [ms]  (t_gyro = t_camera + td)")
    ax.set_ylabel("NCC")
    ax.set_title(
        textwrap.fill("REFUSED: " + est.refused, 90) if est.refused else "camera vs gyro angular rate",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    out.append(_save(fig, plot_dir / "timeoffset.png"))
    if drift is not None:
        fig = Figure(figsize=(10, 5))
        ax = fig.subplots()
        good = [
            (tm, e.td_s * 1e3, e.sigma_s * 1e3)
            for tm, e in drift.windows
            if e.refused is None and e.td_s is not None and e.sigma_s is not None
        ]
        if good:
            ax.errorbar(
                [g[0] for g in good],
                [g[1] for g in good],
                yerr=[g[2] for g in good],
                fmt="o",
                color="#2c3e50",
                capsize=3,
                label="per window",
            )
        if drift.fit is not None and drift.drift_ppm is not None and drift.ci_ppm is not None:
            xs = np.array([drift.windows[0][0], drift.windows[-1][0]])
            ax.plot(
                xs,
                (drift.fit.coef[0] + drift.fit.coef[1] * xs) * 1e3,
                color="#c0392b",
                label=f"drift {drift.drift_ppm:.2f} ppm [{drift.ci_ppm[0]:.2f}, {drift.ci_ppm[1]:.2f}]",
            )
        ax.set_xlabel("time [s]")
        ax.set_ylabel("td [ms]")
        ax.set_title("REFUSED: " + drift.refused if drift.refused else "time offset over the log", fontsize=9)
        ax.legend(fontsize=8)
        fig.tight_layout()
        out.append(_save(fig, plot_dir / "timeoffset_drift.png"))
    return out
