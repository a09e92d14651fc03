"""The calibration report page: verdict and lint first, then the evidence, then where it came from.

Deterministic by construction: no dates but the artifact's own, fixed decimals, views in artifact
order, point clouds thinned by a fixed stride. Numbers that a test checks against the artifact carry
a ``data-key`` attribute.
"""

from __future__ import annotations

from html import escape
from typing import TYPE_CHECKING, Protocol

import numpy as np

from calibctl.core.capture.image_circle import ImageCircle, cells_inside_mask, circle_from_detail
from calibctl.core.intrinsics.report_maps import coverage_grid, edge_gaps_px
from calibctl.workflows.report.report_svg import Plot, colour_bar, heat

if TYPE_CHECKING:
    from collections.abc import Sequence

    from calibctl.artifacts.lint import Finding
    from calibctl.workflows.report.report_data import ReportData

MAX_DOTS = 5000  # per scatter plot (~40 bytes a dot), so a 200-view session stays under 1 MB
COVERAGE_CELLS = (16, 12)
FIELD_CELLS = (16, 12)
_K = (("fx", 0, 0), ("fy", 1, 1), ("cx", 0, 2), ("cy", 1, 2))
_DIST = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
CSS = """body{font-family:sans-serif;max-width:1000px;margin:16px auto;color:#222}
h1{font-size:22px}h2{font-size:17px;border-bottom:1px solid #ccc;margin-top:28px}
table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f2f2f2}td.l,th.l{text-align:left}.accepted{color:#fff;background:#2e7d32}
.rejected{color:#fff;background:#c62828}.badge{padding:3px 10px;border-radius:4px;font-weight:bold}
.error{color:#c62828}.warning{color:#b26a00}.note{color:#555;font-size:13px}.row{display:flex;flex-wrap:wrap;gap:12px}"""


def num(value: float | None, digits: int = 3) -> str:
    """How every number is shown (the tests format the artifact's values the same way)."""
    return "n/a" if value is None else f"{value:.{digits}f}"


def cell(value: str, key: str | None = None, cls: str = "") -> str:
    attr = f' data-key="{escape(key)}"' if key else ""
    cattr = f' class="{cls}"' if cls else ""
    return f"<td{cattr}{attr}>{escape(value)}</td>"


def table(header: list[str], rows: list[str]) -> str:
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    return f"<table><tr>{head}</tr>{''.join(f'<tr>{r}</tr>' for r in rows)}</table>"


class EdgeGate(Protocol):
    """A gate of an evidence edge (LiDAR, IMU) as its artifact stores it."""

    @property
    def gate(self) -> str: ...
    @property
    def passed(self) -> bool: ...
    @property
    def message(self) -> str: ...
    @property
    def hint(self) -> str | None: ...


def gate_table(gates: Sequence[EdgeGate], key: str) -> str:
    """An evidence edge's gates: name, verdict (``data-key`` KEY_GATE), what was measured, what to do."""
    rows = [
        cell(g.gate, cls="l")
        + cell("pass" if g.passed else "FAIL", f"{key}_{g.gate}")
        + cell(g.message, cls="l")
        + cell(g.hint or "", cls="l")
        for g in gates
    ]
    return table(["gate", "verdict", "measured", "what to do"], rows)


def _stride(n: int, most: int = MAX_DOTS) -> int:
    return max(1, -(-n // most))


def _verdict(d: ReportData) -> str:
    art = d.artifact
    active = " (active)" if d.active else ""
    lines = [
        f'<h1>{escape(art.ref)} <span class="badge {art.status}" data-key="status">{art.status}</span>'
        f"{active}</h1>",
        "<p>active now (the version a robot loads by serial): <b "
        f'data-key="active">{"yes" if d.active else "no"}'
        f"</b>. Lint stored at solve time below; <code>calibctl lint --serial {escape(art.serial)}</code> "
        "lints "
        "the active version against today's limits.</p>",
    ]
    return "".join(lines) + lint_block(art.lint)


def lint_block(findings: Sequence[Finding]) -> str:
    """The lint findings as a table (severity, rule, finding, fix), or "lint: clean"."""
    if not findings:
        return '<p data-key="lint">lint: clean</p>'
    rows = [
        cell(f.severity, cls=f"l {f.severity}")
        + cell(f.rule, cls="l")
        + cell(f.message, cls="l")
        + cell(f.fix or "", cls="l")
        for f in findings
    ]
    return table(["severity", "rule", "finding", "fix"], rows)


def _parameters(d: ReportData) -> str:
    art = d.artifact
    sigma = art.stdev.sigma
    rows = []
    for name, r, c in _K:
        s = sigma.get(name) if name in art.model.free_parameters else None
        rows.append(
            cell(name, cls="l")
            + cell(num(art.camera_matrix[r][c], 3), name)
            + cell(num(s, 3) if s is not None else "fixed", f"sigma_{name}")
            + cell("px", cls="l")
        )
    for i, value in enumerate(art.dist_coeffs):
        name = _DIST[i] if i < len(_DIST) else f"d{i}"
        if name in art.model.free_parameters or value != 0:
            s = sigma.get(name)
            rows.append(
                cell(name, cls="l")
                + cell(num(value, 5), name)
                + cell(num(s, 5) if s is not None else "fixed", f"sigma_{name}")
                + cell("", cls="l")
            )
    ho = art.held_out
    summary = (
        f"<p>model {escape(art.model.name)}, {art.image_size[0]}x{art.image_size[1]} px; RMS fit "
        f'<b data-key="rms_px">{num(art.rms_px)}</b> px, held-out <b data-key="held_out_rms_px">'
        f"{num(ho.rms_px)}</b> px ({ho.k_folds}-fold); outer ring fit {num(ho.fit_outer_ring_rms_px)} px / "
        f"held-out {num(ho.outer_ring_rms_px)} px</p>"
    )
    refused = (
        f'<p class="warning">no uncertainty: {escape(art.stdev.refused_reason)}</p>'
        if art.stdev.refused_reason
        else ""
    )
    return (
        "<h2>Parameters (one-sigma)</h2>"
        + summary
        + refused
        + table(["parameter", "value", "sigma", ""], rows)
    )


def _gates(d: ReportData) -> str:
    rows = [
        cell(g.gate, cls="l")
        + cell("pass" if g.passed else "FAIL", f"gate_{g.gate}")
        + cell(f"{g.value:.4g}")
        + cell(f"{g.threshold:g}")
        + cell(g.hint or "", cls="l")
        for g in d.artifact.gates
    ]
    body = table(["gate", "result", "value", "needs", "hint"], rows) if rows else "<p>no gates recorded</p>"
    return "<h2>Capture gates</h2>" + body


def _image_plot(d: ReportData, title: str) -> Plot:
    w, h = d.artifact.image_size
    return Plot(
        title,
        (0.0, float(w)),
        (0.0, float(h)),
        width=520,
        height=int(40 + 456 * h / w) + 12,
        flip_y=True,
        x_label="u (px)",
        y_label="v (px)",
    )


def _coverage(d: ReportData) -> str:
    w, h = d.artifact.image_size
    pts = np.concatenate([v.corners_px for v in d.views])
    grid = coverage_grid(pts, (w, h), COVERAGE_CELLS)
    circle = _image_circle(d)
    if circle is not None:
        return _circle_coverage(d, pts, grid, circle)
    plot = _image_plot(d, f"every corner used ({len(pts)}); cells never reached shaded")
    xe = np.linspace(0, w, COVERAGE_CELLS[0] + 1)
    ye = np.linspace(0, h, COVERAGE_CELLS[1] + 1)
    for r, c in zip(*np.nonzero(grid == 0), strict=True):
        plot.rect(xe[c], ye[r], xe[c + 1], ye[r + 1], "#f4c7c3")
    k = _stride(len(pts))
    plot.dots(pts[::k, 0], pts[::k, 1], "#1565c0", 1.2)
    gaps = edge_gaps_px(pts, (w, h))
    empty = int((grid == 0).sum())
    text = (
        f"<p>{empty} of {grid.size} cells ({COVERAGE_CELLS[0]}x{COVERAGE_CELLS[1]}) never reached "
        f'(<span data-key="empty_cells">{empty}</span>). Nearest corner to each edge: '
        + ", ".join(f'{side} <span data-key="gap_{side}">{gap:.0f}</span> px' for side, gap in gaps.items())
        + (f"; every {k}th corner drawn" if k > 1 else "")
        + "</p>"
    )
    return "<h2>Coverage</h2>" + plot.svg() + text


def _image_circle(d: ReportData) -> ImageCircle | None:
    """The image circle the session's coverage gate recorded (a circular fisheye), else None."""
    gate = next((g for g in d.artifact.gates if g.gate == "coverage"), None)
    return None if gate is None else circle_from_detail(gate.detail)


def _circle_coverage(d: ReportData, pts: np.ndarray, grid: np.ndarray, circle: ImageCircle) -> str:
    """Coverage of a circular fisheye: the circle drawn, cells outside it grey (the lens does not image
    them), only cells inside it can be "never reached"."""
    w, h = d.artifact.image_size
    imaged = cells_inside_mask(circle, (w, h), COVERAGE_CELLS)
    never = (grid == 0) & imaged
    plot = _image_plot(d, f"every corner used ({len(pts)}); outside the circle grey, never reached shaded")
    xe = np.linspace(0, w, COVERAGE_CELLS[0] + 1)
    ye = np.linspace(0, h, COVERAGE_CELLS[1] + 1)
    for mask, fill in ((~imaged, "#dddddd"), (never, "#f4c7c3")):
        for r, c in zip(*np.nonzero(mask), strict=True):
            plot.rect(xe[c], ye[r], xe[c + 1], ye[r + 1], fill)
    a = np.linspace(0.0, 2.0 * np.pi, 97)
    plot.line(
        circle.cx_px + circle.radius_px * np.cos(a), circle.cy_px + circle.radius_px * np.sin(a), "#555555"
    )
    k = _stride(len(pts))
    plot.dots(pts[::k, 0], pts[::k, 1], "#1565c0", 1.2)
    inside = int(imaged.sum())
    text = (
        f"<p>Image circle ({circle.source}): centre ({circle.cx_px:.1f}, {circle.cy_px:.1f}) px, radius "
        f'<span data-key="image_circle_radius_px">{circle.radius_px:.1f}</span> px. '
        f'<span data-key="not_imaged_cells">{grid.size - inside}</span> of {grid.size} cells '
        f"({COVERAGE_CELLS[0]}x{COVERAGE_CELLS[1]}) lie outside it and are not imaged by the lens; "
        f'<span data-key="empty_cells">{int(never.sum())}</span> of the {inside} inside it never reached'
        + (f"; every {k}th corner drawn" if k > 1 else "")
        + ".</p>"
    )
    return "<h2>Coverage</h2>" + plot.svg() + text


def _residual_field(d: ReportData) -> str:
    w, h = d.artifact.image_size
    pts = np.concatenate([v.corners_px for v in d.views])
    res = np.concatenate([v.residuals_px for v in d.views])
    cols, rows = FIELD_CELLS
    ci = np.clip((pts[:, 0] / w * cols).astype(int), 0, cols - 1)
    ri = np.clip((pts[:, 1] / h * rows).astype(int), 0, rows - 1)
    flat = ri * cols + ci
    counts = np.bincount(flat, minlength=rows * cols)
    mean = np.stack([np.bincount(flat, res[:, j], minlength=rows * cols) for j in (0, 1)], axis=1).astype(
        np.float64
    )
    filled = counts > 0
    mean[filled] /= counts[filled, None]
    biggest = float(np.linalg.norm(mean, axis=1).max()) or 1.0
    scale = 0.9 * (w / cols) / biggest
    cell = np.arange(rows * cols)[filled]
    cx = (cell % cols + 0.5) * w / cols
    cy = (cell // cols + 0.5) * h / rows
    plot = _image_plot(d, f"mean residual per cell, x{scale:.0f} (longest {biggest:.3f} px)")
    plot.arrows(cx, cy, mean[filled, 0] * scale, mean[filled, 1] * scale, "#c62828")
    K = d.artifact.camera_matrix
    radius = np.hypot(pts[:, 0] - K[0][2], pts[:, 1] - K[1][2])
    size = np.linalg.norm(res, axis=1)
    k = _stride(len(pts))
    rplot = Plot(
        "residual vs distance from the principal point",
        (0.0, float(radius.max()) * 1.02),
        (0.0, float(size.max()) * 1.05),
        width=440,
        height=300,
        x_label="radius (px)",
        y_label="|residual| (px)",
    )
    rplot.dots(radius[::k], size[::k], "#6a1b9a", 1.2)
    return (
        "<h2>Residuals</h2><p>observed - projected under the stored model and poses; corners the solve "
        f"removed ({len(d.artifact.rejected_corners)}) are not drawn.</p>"
        f'<div class="row">{plot.svg()}{rplot.svg()}</div>'
    )


def _per_view(d: ReportData) -> str:
    views = d.artifact.views
    top = max(v.rms_px for v in views) * 1.1
    plot = Plot(
        "per-view RMS (red: outlier, grey: dropped)",
        (0.0, float(len(views))),
        (0.0, top),
        width=900,
        height=260,
        x_label="view (table below names them)",
        y_label="RMS (px)",
    )
    for i, v in enumerate(views):
        fill = "#9e9e9e" if v.dropped else "#c62828" if v.outlier else "#1565c0"
        plot.rect(i + 0.1, 0.0, i + 0.9, v.rms_px, fill)
    rows = [
        cell(str(i), cls="l")
        + cell(v.name, cls="l")
        + cell(num(v.rms_px), f"view_rms_{i}")
        + cell(num(v.worst_corner_px))
        + cell("outlier" if v.outlier else "", cls="l")
        + cell("dropped" if v.dropped else "", cls="l")
        for i, v in enumerate(views)
    ]
    return (
        "<h2>Per-view RMS</h2>"
        + plot.svg()
        + table(["#", "view", "RMS px", "worst corner px", "flag", ""], rows)
    )


def _held_out(d: ReportData) -> str:
    ho = d.artifact.held_out

    def rows(bins, prefix):
        return [
            cell(b.label, cls="l")
            + cell(num(b.fit_rms_px), f"{prefix}_fit_{i}")
            + cell(num(b.held_out_rms_px), f"{prefix}_held_{i}")
            + cell(str(b.count))
            for i, b in enumerate(bins)
        ]

    header = ["bin", "fit RMS px", "held-out RMS px", "corners"]
    return (
        f"<h2>Held-out RMS ({ho.k_folds}-fold; intrinsics frozen, poses re-fitted)</h2>"
        f'<div class="row">{table(header, rows(ho.by_radius, "ring"))}'
        f"{table(header, rows(ho.by_octant, 'octant'))}</div>"
    )


def _uncertainty(d: ReportData) -> str:
    m = d.uncertainty
    if m is None:
        return (
            "<h2>Projection uncertainty</h2><p>not available: this version stores no covariance "
            f"({escape(d.artifact.stdev.refused_reason or 'made before calibctl stored it')}).</p>"
        )
    w, h = d.artifact.image_size
    # nan: a fisheye pixel beyond 88 deg off-axis, where cv2.fisheye projects nothing (report_maps)
    lo, hi = float(np.nanmin(m.sigma_px)), float(np.nanmax(m.sigma_px))
    plot = _image_plot(d, "projection one-sigma, worst direction (px)")
    heat(
        plot,
        m.sigma_px,
        np.linspace(0, w, len(m.u_px) + 1),
        np.linspace(0, h, len(m.v_px) + 1),
        lo,
        hi,
        empty="#f2f2f2",
    )
    if d.views:  # where the corners were: the uncertainty grows where they never reached
        pts = np.concatenate([v.corners_px for v in d.views])
        k = _stride(len(pts), MAX_DOTS // 2)
        plot.dots(pts[::k, 0], pts[::k, 1], "#ffffff", 0.8)
    r, c = len(m.v_px) // 2, len(m.u_px) // 2
    return (
        "<h2>Projection uncertainty</h2><p>The stored intrinsic covariance propagated to the projection of "
        "the ray through each pixel (as mrcal's show-projection-uncertainty, without re-fitting the camera "
        "frame); white dots: the corners used. Centre <b "
        f'data-key="uncertainty_centre">{num(float(m.sigma_px[r, c]), 2)}</b> px, worst '
        f'<b data-key="uncertainty_max">{num(hi, 2)}</b> px.</p>' + plot.svg() + colour_bar(lo, hi, "px", 520)
    )


def _distortion(d: ReportData) -> str:
    r, disp = d.distortion
    lo, hi = float(min(disp.min(), 0.0)), float(max(disp.max(), 0.0))
    plot = Plot(
        "radial displacement by the lens (negative: barrel)",
        (0.0, float(r.max()) * 1.02),
        (lo - 0.05 * (hi - lo + 1), hi + 0.05 * (hi - lo + 1)),
        width=520,
        height=300,
        x_label="distance from the principal point, distorted (px)",
        y_label="displacement (px)",
    )
    plot.line(np.array([0.0, float(r.max())]), np.zeros(2), "#999", 1.0, "4 3")
    plot.line(r, disp, "#1565c0")
    return (
        "<h2>Distortion</h2><p>along the ray to the farthest image corner; at that corner "
        f'<span data-key="distortion_corner">{num(float(disp[-1]), 1)}</span> px.</p>' + plot.svg()
    )


def _mm(value_m: float | None) -> str:
    return "n/a" if value_m is None else f"{value_m * 1000:.3f} mm"


def _provenance(d: ReportData) -> str:
    art = d.artifact
    p, b = art.provenance, art.board
    m = b.measurement
    rows = [
        ("board", f"{b.ref}: {b.kind} {b.cols}x{b.rows}"),
        ("square size", f"{m.square_size_m * 1000:.3f} mm +/- {_mm(m.uncertainty_m)} ({m.status})"),
        ("measured with", f"{m.instrument or 'n/a'} by {m.measured_by or 'n/a'} on {m.measured_on or 'n/a'}"),
        ("session", p.session_id or "n/a"),
        ("images", str(len(p.input_image_sha256))),
        ("station / operator", f"{p.station} / {p.operator}"),
        ("created", p.created_at.isoformat()),
        ("calibctl / OpenCV", f"{p.calibctl_version} / {p.opencv_version}"),
        ("imported from", p.imported_from or "-"),
        ("content sha256", f"{art.content_sha256} ({art.content_hash_algorithm})"),
    ]
    body = "".join(f'<tr><th class="l">{escape(k)}</th>{cell(v, cls="l")}</tr>' for k, v in rows)
    return f"<h2>Provenance</h2><table>{body}</table>"


def _diff(d: ReportData) -> str:
    """``calibctl diff`` against the previous accepted version: has this calibration really changed?"""
    x = d.diff
    if x is None and d.diff_note is None:
        return ""  # not asked (a solve's own report)
    if x is None:
        return (
            "<h2>Change from the previous version</h2><p "
            f'class="note">{escape(d.diff_note or "not compared")}</p>'
        )
    keys = list(x.raw_px)
    rows = [
        f'<th class="l">{escape(name)}</th>'
        + "".join(cell(num(values[k], 3), f"diff_{tag}_{k}") for k in keys)
        for name, tag, values in (
            ("as stored", "raw", x.raw_px),
            ("after fitting the rotation", "fit", x.fit_px),
        )
    ]
    sigma = (
        ""
        if x.expected_sigma_px is None
        else (
            f"; the raw difference expected from the two covariances alone: "
            f"median one-sigma {num(x.expected_sigma_px, 3)} px"
        )
    )
    why = "".join(f"<li>{escape(r)}</li>" for r in x.reasons)
    return (
        f"<h2>Change from the previous version</h2><p><code>calibctl diff {escape(x.previous_ref)} "
        f'{escape(d.artifact.ref)}</code>: <b data-key="diff_verdict">{escape(x.verdict)}</b>; implied '
        "rotation "
        f"{num(x.rotation_deg, 4)} deg{sigma}.</p>"
        + table(["projection difference (px)", *keys], rows)
        + (f"<ul>{why}</ul>" if why else "")
    )


def _trends(d: ReportData) -> str:
    """``calibctl fleet trends``: what the robots carrying this serial reported (conditionals, not
    aggregates)."""
    t = d.trends
    if t is None:
        return ""
    counts = ", ".join(f"{n} {k}" for k, n in t["counts"].items())
    lines = []
    s = t.get("rms_vs_temperature_px_per_c")
    if s is not None:
        lines.append(f"RMS vs temperature: {s['slope']:+.4f} +- {s['sigma']:.4f} px/degC (n {s['n']})")
    drift = t.get("td_drift_ppm")
    if drift is not None:
        lines.append(
            f"time offset vs time: {drift['slope']:+.2f} +- {drift['sigma']:.2f} ppm over "
            f"{t['td_span_days']:.1f} days (n {drift['n']})"
        )
    if t.get("gauge"):
        g = t["gauge"]
        lines.append(
            f"gauge ratio: median {g['median']:.4f}, p05..p95 {g['p05']:.4f}..{g['p95']:.4f} (n {g['n']})"
        )
    for name in ("check_verdicts", "triage_verdicts"):
        if t.get(name):
            lines.append(f"{name.split('_')[0]}: " + ", ".join(f"{n} {v}" for v, n in t[name].items()))
    f = t.get("fleet")
    if f is not None:
        lines.append(
            f"this camera's mean check RMS {f['this_mean_rms_px']:.3f} px, rank {f['rank']} of "
            f"{f['serials']} "
            f"serials (others' median {f['others_median_rms_px']:.3f} px)"
        )
    bins = [
        cell(f"{b['from_c']:g}..{b['to_c']:g}", cls="l")
        + cell(str(b["n"]))
        + cell(num(b["mean"]))
        + cell(num(b["max"]))
        for b in t.get("rms_by_temperature", [])
    ]
    findings = "".join(f'<li class="warning">{escape(x)}</li>' for x in t.get("findings", []))
    return (
        f'<h2>Field health (robots\' reports)</h2><p data-key="trends_counts">{escape(counts)}</p><ul>'
        + "".join(f"<li>{escape(x)}</li>" for x in lines)
        + findings
        + "</ul>"
        + (table(["temperature (degC)", "n", "RMS mean (px)", "RMS max (px)"], bins) if bins else "")
    )


def render_html(d: ReportData) -> str:
    """The whole page as one string: inline CSS and SVG, no script, nothing fetched."""
    parts = [_verdict(d), _parameters(d), _gates(d)]
    if d.views:
        parts += [_coverage(d), _residual_field(d)]
    else:
        parts.append(
            f'<h2>Coverage and residuals</h2><p class="note">{escape(d.corners_note or "no corners")}</p>'
        )
    parts += [
        _per_view(d) if d.artifact.views else "",
        _held_out(d),
        _uncertainty(d),
        _distortion(d),
        _diff(d),
        _trends(d),
        _provenance(d),
    ]
    title = escape(f"calibctl report {d.artifact.ref}")
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
        f"<style>{CSS}</style></head><body>{''.join(parts)}</body></html>\n"
    )
