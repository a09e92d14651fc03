"""calibctl report --rig: one stored rig calibration -> one self-contained HTML page.

Same shape and rules as the camera report (``report_html``): verdict and lint first, fixed decimals,
no dates but the artifact's own, inline SVG, no script; numbers a test checks carry ``data-key``.
It shows the baselines with sigma, the T_root_cam tree (edges and the composed transforms, drawn from
above), the held-out epipolar RMS and rectified vertical disparity per pair, loop closure, and each
member's calibration with its verdict and a link to its own report by serial@version. A rig with a
camera-LiDAR edge gets a LiDAR section: T_lidar_cam with one-sigma, gates, fit and held-out figures, scan
outcomes, and the sweep drawn over its image through the stored T when the solve's files are still where
they were, unchanged (the store keeps neither; the page says so rather than drawing anything else).
A camera-IMU edge gets its own section (``workflows.imu.imu_report``), drawn from the stored evidence.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from html import escape
from pathlib import Path

import numpy as np

from calibctl.artifacts.lint import Finding, has_errors
from calibctl.artifacts.rig import RigCalibration
from calibctl.config import Settings
from calibctl.errors import NotFoundError
from calibctl.files import write_atomic
from calibctl.workflows.imu.imu_report import imu_section
from calibctl.workflows.lidar.lidar_overlay import report_overlay
from calibctl.workflows.report.report import default_path
from calibctl.workflows.report.report_html import CSS, cell, gate_table, lint_block, num, table
from calibctl.workflows.report.report_svg import Plot
from calibctl.workflows.rig.rig_lint import lint_rig, parse_rig_ref
from calibctl.workflows.store_admin.records import open_store


@dataclass(frozen=True)
class MemberVerdict:
    """A member calibration as the rig used it, and what the store says about that version now."""

    serial: str
    version: int
    status: str  # accepted / rejected, or "missing" when the version is not in this store
    active: bool
    held_out_rms_px: float | None
    report_file: str  # the camera report's default file name, linked relatively


@dataclass(frozen=True)
class RigReportData:
    calibration: RigCalibration
    active: bool
    members: list[MemberVerdict]
    T_root_cam: dict[
        str, np.ndarray
    ]  # frame (camera serial or LiDAR) -> (4, 4), metres, composed along the tree
    lint_now: list[Finding] = field(
        default_factory=list
    )  # `calibctl lint --rig RIG@N` against the store today
    lidar_overlays: dict[str, tuple[str | None, str]] = field(
        default_factory=dict
    )  # "lidar:CAM" -> (uri, caption)


def compose_tree(cal: RigCalibration) -> dict[str, np.ndarray]:
    """T_root_frame of every frame connected to the root: cameras, and frames met from their child (a LiDAR
    edge ``lidar -> CAM0`` hangs the LiDAR above the root camera: T_root_lidar = T_lidar_cam^-1)."""
    out = {cal.root: np.eye(4)}
    grew = True
    while grew:
        grew = False
        for edge in cal.edges:
            T = np.asarray(edge.T_parent_child, np.float64)
            if edge.parent in out and edge.child not in out:
                out[edge.child] = out[edge.parent] @ T
                grew = True
            elif edge.child in out and edge.parent not in out:
                out[edge.parent] = out[edge.child] @ np.linalg.inv(T)
                grew = True
    return out


def gather_rig(settings: Settings, ref: str) -> RigReportData:
    """Read RIG or RIG@N (default: active) and the members' calibrations. Unknown rig/version: exit 2."""
    name, version = parse_rig_ref(ref)
    with open_store(settings) as store:
        store.get_rig(name)  # an unknown rig is named as such, with the known ones
        cal = store.get_rig_calibration(name, version)
        active = store.active_rig_version(name) == cal.version
        members = []
        for m in cal.members:
            try:
                art = store.get_artifact(m.serial, m.version)
            except NotFoundError:
                members.append(MemberVerdict(m.serial, m.version, "missing", False, None, ""))
                continue
            members.append(
                MemberVerdict(
                    m.serial,
                    m.version,
                    art.status,
                    store.active_version(m.serial) == m.version,
                    art.held_out.rms_px,
                    default_path(art, Path(".")).name,
                )
            )
    lint_now = lint_rig(settings, f"{cal.rig}@{cal.version}").findings
    overlays = {f"{ev.parent_frame}:{ev.child_frame}": report_overlay(settings, ev) for ev in cal.lidar}
    return RigReportData(cal, active, members, compose_tree(cal), lint_now, overlays)


def _verdict(d: RigReportData) -> str:
    cal = d.calibration
    ref = f"{cal.rig}@{cal.version}"
    now = "FAIL" if has_errors(d.lint_now) else "pass"
    lines = [
        f'<h1>rig {escape(ref)} <span class="badge {cal.status}" data-key="status">{cal.status}</span>'
        f"{' (active)' if d.active else ''}</h1>",
        f'<p>active now: <b data-key="active">{"yes" if d.active else "no"}</b>; lint now '
        f"(<code>calibctl lint --rig {escape(ref)}</code>, the store as it is today: a member re-calibrated "
        f'since the solve fails it): <b class="{"rejected" if now == "FAIL" else "accepted"}" '
        f'data-key="lint_now">{now}</b></p>',
        "<h2>Lint now</h2>",
        lint_block(d.lint_now).replace('data-key="lint"', 'data-key="lint_now_clean"'),
        "<h2>Lint at solve time</h2>",
    ]
    return "".join(lines) + lint_block(cal.lint)


def _pairs(d: RigReportData) -> str:
    rows = []
    for p in d.calibration.pairs:
        key = f"{p.a}-{p.b}"
        rows.append(
            cell(key, cls="l")
            + cell(num(p.baseline_mm, 3), f"baseline_{key}")
            + cell(num(p.sigma_baseline_mm, 3), f"sigma_baseline_{key}")
            + cell(num(p.rotation_deg, 3))
            + cell(num(p.sigma_rotation_deg, 3))
            + cell(str(p.shared_views))
            + cell(num(p.epipolar_rms_px), f"epipolar_{key}")
            + cell(num(p.epipolar_max_px))
            + cell(num(p.rectified_rms_px), f"vertical_{key}")
            + cell(num(p.rectified_max_px))
        )
    return "<h2>Pairs (one-sigma; held-out epipolar error and rectified vertical disparity)</h2>" + table(
        [
            "pair",
            "baseline mm",
            "sigma mm",
            "rotation deg",
            "sigma deg",
            "shared views",
            "epipolar RMS px",
            "max px",
            "vertical RMS px",
            "max px",
        ],
        rows,
    )


def _tree(d: RigReportData) -> str:
    cal = d.calibration
    rows = [
        cell(f"{e.parent} -> {e.child}", cls="l")
        + cell(e.source, cls="l")
        + cell(num(e.translation_mm, 3), f"edge_{e.parent}-{e.child}")
        + cell(num(e.sigma_translation_mm, 3))
        + cell(num(e.rotation_deg, 3))
        + cell(num(e.sigma_rotation_deg, 3))
        for e in cal.edges
    ]
    poses = []
    for serial, T in d.T_root_cam.items():
        t_mm = T[:3, 3] * 1000
        poses.append(
            cell(f"T_{cal.root}_{serial}", cls="l")
            + "".join(
                cell(num(float(v), 2), f"t_{serial}_{axis}") for v, axis in zip(t_mm, "xyz", strict=True)
            )
        )
    return (
        "<h2>Tree (T_parent_child, root "
        + escape(cal.root)
        + ")</h2>"
        + table(["edge", "source", "|t| mm", "sigma mm", "rotation deg", "sigma deg"], rows)
        + "<p>Composed T_root_frame translations (root frame, mm; cameras and LiDARs):</p>"
        + table(["transform", "x", "y", "z"], poses)
        + _top_view(d)
    )


def _top_view(d: RigReportData) -> str:
    """The frames seen from above (x right, z forward, root frame): each camera with its optical axis (z),
    each LiDAR (a frame of a lidar-board edge) in green with its forward axis (x)."""
    xs = {s: T[:3, 3] * 1000 for s, T in d.T_root_cam.items()}
    pts = np.array(list(xs.values()))
    span = float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 2]), 50.0))
    cx, cz = float(pts[:, 0].mean()), float(pts[:, 2].mean())
    half = 0.7 * span
    lidars = {e.parent_frame for e in d.calibration.lidar}
    plot = Plot(
        "frames from above (root frame)",
        (cx - half, cx + half),
        (cz - half, cz + half),
        width=420,
        height=420,
        x_label="x (mm)",
        y_label="z (mm)",
    )
    for serial, T in d.T_root_cam.items():
        p = xs[serial]
        lidar = serial in lidars
        axis = T[:3, 0 if lidar else 2] * 0.25 * span
        plot.line(np.array([p[0], p[0] + axis[0]]), np.array([p[2], p[2] + axis[2]]), "#1565c0")
        plot.dots(np.array([p[0]]), np.array([p[2]]), "#2e7d32" if lidar else "#c62828", 4.0)
        plot.text(float(p[0]), float(p[2]) - 0.06 * span, serial, size=10)
    return plot.svg()


def _loops(d: RigReportData) -> str:
    loops = d.calibration.loops
    if not loops:
        return "<h2>Loop closure</h2><p>no loops (fewer than three cameras, or a tree without a cycle)</p>"
    rows = [
        cell(" -> ".join(lp.cycle), cls="l")
        + cell(num(lp.rotation_deg, 4))
        + cell(num(lp.sigma_rotation_deg, 4))
        + cell(num(lp.translation_mm, 3), f"loop_{i}")
        + cell(num(lp.sigma_translation_mm, 3))
        + cell(num(lp.mahalanobis, 2))
        for i, lp in enumerate(loops)
    ]
    return "<h2>Loop closure</h2>" + table(
        ["cycle", "rotation deg", "sigma deg", "translation mm", "sigma mm", "Mahalanobis"], rows
    )


def _lidar(d: RigReportData) -> str:
    """One block per camera-LiDAR result of this version (accepted edges and the rejected result alike)."""
    out = []
    for ev in d.calibration.lidar:
        key = f"{ev.parent_frame}:{ev.child_frame}"
        k = f"{ev.parent_frame}-{ev.child_frame}"
        head = (
            f'<h3>{escape(ev.parent_frame)} -> {escape(ev.child_frame)} <span class="badge {ev.status}" '
            f'data-key="lidar_status_{escape(k)}">{ev.status}</span></h3><p>camera {escape(ev.camera)}, '
            "board "
            f"{escape(ev.board)}; scans {escape(ev.scans)}, images {escape(ev.images)}</p>"
        )
        t, m = ev.transform, ev.metrics
        body = ""
        if t is not None:
            T = np.array(t.T_lidar_cam)
            rows = [
                cell(f"{a}", cls="l")
                + cell(num(float(T[i, 3]) * 1e3, 1), f"lidar_t_{k}_{a}")
                + cell(num(t.sigma_translation_mm[i], 1), f"lidar_sigma_t_{k}_{a}")
                + cell(num(float(np.degrees(t.rpy_rad[i])), 3))
                + cell(num(t.sigma_rotation_deg[i], 3), f"lidar_sigma_r_{k}_{a}")
                for i, a in enumerate("xyz")
            ]
            body += (
                "<p>T_lidar_cam: p_lidar = R p_cam + t; rotation as roll, pitch, yaw (R = Rz Ry Rx) and "
                "one-sigma about LiDAR x, y, z"
                + ("" if ev.status == "accepted" else "; rejected: not an edge of the tree")
                + "</p>"
                + table(["axis", "t mm", "sigma mm", "roll/pitch/yaw deg", "sigma deg"], rows)
            )
        if m is not None:
            figures = [
                ("poses", "poses", str(m.poses)),
                ("point-to-plane RMS mm", "plane", num(m.plane_rms_mm, 2)),
                ("held-out point-to-plane RMS mm", "held_out_plane", num(m.held_out_plane_rms_mm, 2)),
                ("edge RMS mm", "edge", num(m.edge_rms_mm, 2)),
                ("held-out edge RMS mm", "held_out_edge", num(m.held_out_edge_rms_mm, 2)),
                ("edge RMS px (image)", "edge_px", num(m.projected_edge_rms_px, 2)),
                (
                    "held-out edge RMS px (image)",
                    "held_out_edge_px",
                    num(m.held_out_projected_edge_rms_px, 2),
                ),
                ("folds", "folds", str(m.folds)),
                (
                    "board dimension error mm (width, height)",
                    "dimension",
                    ", ".join(num(v, 1) for v in m.dimension_error_mean_mm),
                ),
            ]
            body += table(
                ["figure", "value"],
                [cell(a, cls="l") + cell(v, f"lidar_{name}_{k}") for a, name, v in figures],
            )
        counts: dict[str, int] = {}
        for r in ev.scans_outcomes:
            counts[r.outcome] = counts.get(r.outcome, 0) + 1
        body += (
            gate_table(ev.gates, f"lidar_gate_{k}")
            + "<p>scans: "
            + escape(", ".join(f"{o} {n}" for o, n in sorted(counts.items())))
            + "</p>"
        )
        uri, caption = d.lidar_overlays.get(key, (None, "not drawn"))
        body += (
            f'<figure><img src="{uri}" alt="LiDAR over image" data-key="lidar_overlay_{escape(k)}" '
            f'style="max-width:100%"><figcaption>{escape(caption)}</figcaption></figure>'
            if uri
            else f'<p data-key="lidar_overlay_missing_{escape(k)}">Overlay {escape(caption)}</p>'
        )
        out.append(head + body)
    return "<h2>LiDAR</h2>" + "".join(out) if out else ""


def _members(d: RigReportData) -> str:
    cal = d.calibration
    rows = []
    for m in d.members:
        ref = f"{m.serial}@{m.version}"
        link = f'<a href="{escape(m.report_file)}">{escape(ref)}</a>' if m.report_file else escape(ref)
        rows.append(
            f'<td class="l">{link}</td>'
            + cell(m.status, f"member_{m.serial}", cls=f"l {m.status}")
            + cell("yes" if m.active else "no")
            + cell(num(m.held_out_rms_px), f"camera_held_out_{m.serial}")
            + cell(num(cal.held_out_rms_px.get(m.serial)), f"rig_held_out_{m.serial}")
            + cell(num(cal.fit_rms_px.get(m.serial)))
        )
    return (
        "<h2>Members</h2><p>Each member's calibration as this rig used it; the link opens its own report "
        "(`calibctl report SERIAL@N`, written beside this page).</p>"
        + table(
            ["calibration", "verdict", "active", "camera held-out px", "rig held-out px", "rig fit px"], rows
        )
    )


def _provenance(d: RigReportData) -> str:
    cal = d.calibration
    p = cal.provenance
    rows = [
        ("solver", f"{cal.solver}, intrinsics {'refined' if cal.refine_intrinsics else 'held'}"),
        ("held-out folds", str(cal.held_out_folds)),
        ("station / operator", f"{p.station} / {p.operator}"),
        ("created", p.created_at.isoformat()),
        ("calibctl / OpenCV", f"{p.calibctl_version} / {p.opencv_version}"),
        ("session", p.session_id or "n/a"),
        ("content sha256", cal.content_sha256),
    ]
    gates = "".join(
        f"<li>{escape(g.gate)}: {'pass' if g.passed else 'FAIL'} ({escape(g.message)})</li>"
        for g in cal.gates
    )
    body = "".join(f'<tr><th class="l">{escape(k)}</th>{cell(v, cls="l")}</tr>' for k, v in rows)
    return f"<h2>Gates and provenance</h2><ul>{gates}</ul><table>{body}</table>"


def render_rig_html(d: RigReportData) -> str:
    """The whole rig page as one string: inline CSS and SVG, no script, nothing fetched."""
    parts = [
        _verdict(d),
        _pairs(d),
        _tree(d),
        _lidar(d),
        imu_section(d.calibration.imu),
        _loops(d),
        _members(d),
        _provenance(d),
    ]
    title = escape(f"calibctl rig report {d.calibration.rig}@{d.calibration.version}")
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
        f"<style>{CSS}</style></head><body>{''.join(parts)}</body></html>\n"
    )


def write_rig_report(
    settings: Settings, ref: str, out: Path | None, *, force: bool
) -> tuple[Path, RigReportData]:
    """Render RIG[@N] and write it atomically to ``out`` (default RIG-vN-rig-report.html here)."""
    data = gather_rig(settings, ref)
    cal = data.calibration
    path = out if out is not None else Path.cwd() / f"{cal.rig}-v{cal.version}-rig-report.html"
    write_atomic(path, render_rig_html(data), force=force)
    return path, data
