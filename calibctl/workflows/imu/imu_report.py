"""The camera-IMU section of ``calibctl report --rig`` (drawn by ``workflows/rig/report_rig.py``).

Everything comes from the stored evidence (``ImuEdgeResult``), so the page needs no input file and is
byte-identical when regenerated: T_imu_cam with one-sigma, td with its sigma and CRLB, the gates with
their verdicts, the fit figures, the gyro against the camera's board-derived rate after alignment (td
applied), the residuals over time and over image rows with the row test's verdict. A result stored
before the series existed gets the tables and a line saying how to draw the plots.
"""

from __future__ import annotations

from html import escape

import numpy as np

from calibctl.artifacts.imu import ImuEdgeResult, ImuModelEstimate, ImuRowTest, ImuSeries
from calibctl.core.extrinsics import se3
from calibctl.workflows.report.report_html import cell, gate_table, num, table
from calibctl.workflows.report.report_svg import Plot

AXIS_COLOURS = ("#c62828", "#2e7d32", "#1565c0")  # IMU x, y, z


def _column(values: list, axis: int | None = None) -> np.ndarray:
    """A stored list (None: an empty bin) as floats with NaN."""
    picked = [v if axis is None else v[axis] for v in values]
    return np.array([np.nan if v is None else v for v in picked], np.float64)


def _span(*arrays: np.ndarray, symmetric: bool = False) -> tuple[float, float]:
    finite = np.concatenate([a[np.isfinite(a)] for a in arrays])
    if finite.size == 0:
        return (-1.0, 1.0) if symmetric else (0.0, 1.0)
    if symmetric:
        top = float(np.max(np.abs(finite))) * 1.05 or 1.0
        return -top, top
    return min(0.0, float(finite.min())), float(finite.max()) * 1.05 or 1.0


def _line(plot: Plot, x: np.ndarray, y: np.ndarray, colour: str) -> None:
    ok = np.isfinite(y)
    if np.count_nonzero(ok) >= 2:
        plot.line(x[ok], y[ok], colour, width=1.2)


def _rates(series: ImuSeries) -> str:
    t = np.array(series.t_s)
    gyro = [_column(series.gyro_rad_s, a) for a in range(3)]
    cam = [_column(series.camera_rate_rad_s, a) for a in range(3)]
    plot = Plot(
        "gyro (lines) and camera rate (dots) in the IMU frame, td applied",
        (float(t[0]), float(t[-1])),
        _span(*gyro, *cam, symmetric=True),
        width=960,
        height=300,
        x_label="IMU clock (s from the first sample); red x, green y, blue z",
        y_label="rad/s",
    )
    for a in range(3):
        _line(plot, t, gyro[a], AXIS_COLOURS[a])
        ok = np.isfinite(cam[a])
        plot.dots(t[ok], cam[a][ok], AXIS_COLOURS[a], 1.6)
    return plot.svg()


def _residuals_over_time(series: ImuSeries) -> str:
    t = np.array(series.t_s)
    out = []
    for title, values, unit in (
        ("reprojection RMS", series.corner_rms_px, "px"),
        ("gyro residual RMS", series.gyro_rms_rad_s, "rad/s"),
        ("accelerometer residual RMS", series.accel_rms_m_s2, "m/s^2"),
    ):
        y = _column(values)
        plot = Plot(title, (float(t[0]), float(t[-1])), _span(y), width=320, height=200, y_label=unit)
        _line(plot, t, y, "#1565c0")
        out.append(plot.svg())
    return '<div class="row">' + "".join(out) + "</div>"


def _rows(test: ImuRowTest) -> str:
    row = np.array([b.row_px for b in test.rows])
    mean = _column([b.time_residual_us for b in test.rows])
    sigma = _column([b.sigma_us for b in test.rows])
    ok = np.isfinite(mean) & np.isfinite(sigma)
    fit = test.offset_us + test.slope_us_per_row * (row - test.principal_row_px)
    pad = float(np.median(np.diff(row))) if row.size > 1 else 1.0
    plot = Plot(
        "time residual over image rows (dots: bins with white-noise one-sigma; line: the fit)",
        (float(row[0]) - pad, float(row[-1]) + pad),
        _span(mean[ok] + sigma[ok], mean[ok] - sigma[ok], fit, symmetric=True),
        width=480,
        height=260,
        x_label="image row (px)",
        y_label="us",
    )
    for r, m, s in zip(row[ok], mean[ok], sigma[ok], strict=True):
        plot.line(np.array([r, r]), np.array([m - s, m + s]), "#888", width=1.0)
    plot.dots(row[ok], mean[ok], "#1565c0", 2.5)
    plot.line(row, fit, "#c62828", width=1.2)
    return plot.svg()


def _estimate(ev: ImuEdgeResult, k: str) -> str:
    e = ev.estimate
    if e is None:
        return '<p data-key="imu_estimate_' + escape(k) + '">no estimate (refused before solving)</p>'
    T = np.array(e.T_imu_cam)
    rotvec_deg = np.degrees(se3.rotvecs_from_rotations(T[None, :3, :3])[0])
    rows = [
        cell(a, cls="l")
        + cell(num(float(T[i, 3]) * 1e3, 2), f"imu_t_{k}_{a}")
        + cell(num(e.sigma_translation_mm[i], 2), f"imu_sigma_t_{k}_{a}")
        + cell(num(float(rotvec_deg[i]), 3))
        + cell(num(e.sigma_rotation_deg[i], 4), f"imu_sigma_r_{k}_{a}")
        for i, a in enumerate("xyz")
    ]
    td = [
        cell("td ms", cls="l")
        + cell(num(e.td_s * 1e3, 4), f"imu_td_{k}")
        + cell("held" if e.td_held else num(e.sigma_td_ms, 4), f"imu_sigma_td_{k}")
        + cell(num(e.td_crlb_ms, 4), f"imu_td_crlb_{k}")
    ]
    if e.line_delay_s is not None:
        td.append(
            cell("line delay us/row", cls="l")
            + cell(num(e.line_delay_s * 1e6, 3), f"imu_line_delay_{k}")
            + cell(num(e.sigma_line_delay_us, 3))
            + cell("")
        )
    held = f"<p>td held: {escape(e.td_held_reason)}</p>" if e.td_held and e.td_held_reason else ""
    return (
        "<p>T_imu_cam: p_imu = R p_cam + t; rotation as a rotation vector, one-sigma about IMU x, y, z"
        + ("" if ev.status == "accepted" else "; rejected: not an edge of the tree")
        + "</p>"
        + table(["axis", "t mm", "sigma mm", "rotation vector deg", "sigma deg"], rows)
        + f"<p>td: {escape(ev.td_convention)}; CRLB: td's bound with every other state known</p>"
        + table(["", "value", "one-sigma", "CRLB"], td)
        + held
        + _imu_model(e.imu_model, k)
    )


def _imu_model(m: ImuModelEstimate | None, k: str) -> str:
    """The IMU model's states with their one-sigma and prior (nothing for the calibrated IMU)."""
    if m is None:
        return ""
    rows = [
        cell(name, cls="l")
        + cell(num(v, 6), f"imu_model_{k}_{name}")
        + cell(num(m.sigmas[name], 6), f"imu_model_sigma_{k}_{name}")
        + cell(num(m.prior_sigmas[name], 4))
        for name, v in m.states.items()
    ]
    return (
        f'<p>IMU model <b data-key="imu_model_{escape(k)}">{escape(m.model)}</b>: deviation from identity '
        "(M - I lower triangles, C_gyro_i as a rotation vector in rad, g-sensitivity in (rad/s)/(m/s^2)); "
        f"the data's least prior-scaled information {m.min_information:.1f}</p>"
        + table(["state", "value", "one-sigma", "prior sigma"], rows)
    )


def _figures(ev: ImuEdgeResult, k: str) -> str:
    m = ev.metrics
    if m is None:
        return ""
    held = m.held_out_corner_rms_px
    figures = [
        ("frames / corners / IMU samples", "counts", f"{m.frames} / {m.corners} / {m.imu_samples}"),
        ("corners left out (over 5 robust sigmas)", "left_out", str(m.corners_left_out)),
        ("reprojection RMS px", "corner_rms", num(m.corner_rms_px, 3)),
        ("gyro RMS rad/s", "gyro_rms", num(m.gyro_rms_rad_s, 5)),
        ("accelerometer RMS m/s^2", "accel_rms", num(m.accel_rms_m_s2, 4)),
        (
            f"held-out reprojection RMS px, worst of {m.folds} folds",
            "held_out",
            num(max(held), 3) if held else "n/a",
        ),
    ]
    return table(["figure", "value"], [cell(a, cls="l") + cell(v, f"imu_{n}_{k}") for a, n, v in figures])


def imu_section(results: list[ImuEdgeResult]) -> str:
    """One block per camera-IMU result of a rig version (accepted edges and a rejected result alike)."""
    out = []
    for ev in results:
        k = f"{ev.parent_frame}-{ev.child_frame}"
        body = (
            f'<h3>{escape(ev.parent_frame)} -> {escape(ev.child_frame)} <span class="badge {ev.status}" '
            f'data-key="imu_status_{escape(k)}">{ev.status}</span></h3><p>camera {escape(ev.camera)} '
            f"(intrinsics held), board {escape(ev.board or 'from the corner files')}; recording "
            f"{escape(ev.recording)}; IMU noise {escape(ev.noise.source)}</p>"
            + _estimate(ev, k)
            + gate_table(ev.gates, f"imu_gate_{k}")
            + _figures(ev, k)
        )
        if ev.row_test is not None:
            verdict = "suspected" if ev.row_test.significant else "no"
            body += (
                f'<p>row test (rolling shutter <b data-key="imu_rolling_shutter_{escape(k)}">{verdict}</b>): '
                f'<span data-key="imu_row_test_{escape(k)}">{escape(ev.row_test.message)}</span></p>'
            )
        if ev.series is not None and ev.row_test is not None:
            body += _rates(ev.series) + _residuals_over_time(ev.series) + _rows(ev.row_test)
        elif ev.series is not None:
            body += _rates(ev.series) + _residuals_over_time(ev.series)
        elif ev.estimate is not None:
            body += (
                f'<p data-key="imu_plots_missing_{escape(k)}">No rate or residual plots: this result was '
                "stored without them; solve again (`calibctl imu solve ... --rig`) to draw them.</p>"
            )
        out.append(body)
    return "<h2>Camera-IMU</h2>" + "".join(out) if out else ""
