"""Human reports for calibrations: reads like the seed's sentence, 'fx = 1002.31 +/- 0.84 px'."""

from __future__ import annotations

from typing import TYPE_CHECKING

from rich import box
from rich.table import Table

from calibctl.cli.plain_text import finding_lines
from calibctl.cli.render import fmt_px, shown, stdout
from calibctl.errors import named_list

if TYPE_CHECKING:
    from calibctl.artifacts.calibration import CalibrationArtifact
    from calibctl.artifacts.lint import Finding
    from calibctl.artifacts.session import GateResult

_K_NAMES = (("fx", 0, 0), ("fy", 1, 1), ("cx", 0, 2), ("cy", 1, 2))
_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
REJECTED_CORNERS_SHOWN = 5


def _with_sigma(name: str, value: float, sigma: dict[str, float], unit: str, digits: int) -> str:
    s = sigma.get(name)
    core = f"{name} = {value:.{digits}f}"
    if s is None:
        return f"{core} {unit} (fixed)" if unit else f"{core} (fixed)"
    return f"{core} +/- {s:.{digits}f} {unit}".rstrip()


def print_calibration(art: CalibrationArtifact, active: bool | None = None) -> None:
    marker = "" if active is None else (" (active)" if active else "")
    status_style = "green" if art.status == "accepted" else "red"
    stdout.print(
        f"[bold]{shown(art.ref)}[/bold]{marker}  [{status_style}]{art.status}[/{status_style}]  "
        f"{art.image_size[0]}x{art.image_size[1]}  model {shown(art.model.name)}  board "
        f"{shown(art.board.ref)} "
        f"({art.board.measurement.square_size_m * 1000:.3f} mm, {art.board.measurement.status})"
    )
    sigma = art.stdev.sigma
    for name, r, c in _K_NAMES:
        free = name in art.model.free_parameters
        text = _with_sigma(name, art.camera_matrix[r][c], sigma if free else {}, "px", 2)
        stdout.print(f"  {text}")
    for i, value in enumerate(art.dist_coeffs):
        name = _DIST_NAMES[i] if i < len(_DIST_NAMES) else f"d{i}"
        if name in art.model.free_parameters:
            stdout.print(f"  {_with_sigma(name, value, sigma, '', 4)}")
    if art.stdev.refused_reason:
        stdout.print(f"  [yellow]no uncertainty: {shown(art.stdev.refused_reason)}[/yellow]")
    vl = art.stdev.view_level
    if vl is not None and vl.used == "view-level":
        stdout.print(
            f"  [yellow]sigma x {vl.sigma_factor:.2f}: the {vl.views} views scatter more than their corner "
            "noise "
            "explains (per-view error: board warp, motion, sync), so the view-level sigma is "
            "reported[/yellow]"
        )
    ho = art.held_out
    stdout.print(
        f"  RMS fit {fmt_px(art.rms_px)} px / held-out {fmt_px(ho.rms_px)} px ({ho.k_folds}-fold); "
        f"outer ring fit {fmt_px(ho.fit_outer_ring_rms_px)} px / held-out {fmt_px(ho.outer_ring_rms_px)} px"
    )
    n_out = sum(v.outlier for v in art.views)
    n_drop = sum(v.dropped for v in art.views)
    stdout.print(f"  views {len(art.views)} ({n_out} outlier, {n_drop} dropped)")
    if art.rejected_corners:
        listed = named_list(
            [f"{shown(c.view)} id {c.corner_id} ({c.residual_px:.1f} px)" for c in art.rejected_corners],
            REJECTED_CORNERS_SHOWN,
        )
        stdout.print(f"  corners removed from the solve: {len(art.rejected_corners)}: {listed}")
    if art.gates:
        print_gates(art.gates)
    print_findings(art.lint)


def print_gates(gates: list[GateResult]) -> None:
    for g in gates:
        # a proxy the projection gate overruled is guidance: it says what to capture, it does not refuse
        mark = (
            "[green]pass[/green]"
            if g.passed
            else "[yellow]guide[/yellow]"
            if g.advisory
            else "[red]FAIL[/red]"
        )
        value = (
            f"{g.value:.3g}" if g.gate in ("observability", "one_camera", "projection") else f"{g.value:g}"
        )
        value = "-" if g.gate == "one_camera" and g.value == 0.0 else value  # not checked, or no split found
        needs = {"one_camera": "two cameras from", "projection": "at most"}.get(
            g.gate, "needs"
        )  # upper limits
        line = f"  gate {g.gate:<13} {mark}  {value} ({needs} {g.threshold:g})"
        circle = [
            g.detail.get(k) for k in ("image_circle_cx_px", "image_circle_cy_px", "image_circle_radius_px")
        ]
        if g.gate == "coverage" and all(isinstance(v, int | float) for v in circle):
            line += (
                f" cells inside the image circle ({circle[0]:.1f}, {circle[1]:.1f}) r {circle[2]:.1f} px, "
                f"{shown(str(g.detail.get('image_circle_source', 'given')))}"
            )
        if not g.passed and g.hint:
            line += f" -> {shown(g.hint)}"
        stdout.print(line)


def print_findings(findings: list[Finding]) -> None:
    for line in finding_lines(findings, lambda colour, word: f"[{colour}]{word}[/{colour}]", shown):
        stdout.print(line)


def history_table(rows: list, serial: str) -> Table:
    table = Table(
        title=f"calibration history of {shown(serial)} (rms, sigma(fx), held-out outer ring: px)",
        title_justify="left",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
    )
    for col in ("ver", "status", "act", "rms", "sig fx", "outer", "created UTC"):
        table.add_column(col, no_wrap=True)
    for col in ("board", "station", "operator"):
        table.add_column(col, overflow="fold")
    for r in rows:
        table.add_row(
            str(r.version),
            r.status,
            "*" if r.active else "",
            fmt_px(r.rms_px),
            fmt_px(r.sigma_fx_px, 2),
            fmt_px(r.held_out_outer_rms_px),
            r.created_at[:16].replace("T", " "),
            shown(r.board),
            shown(r.station),
            shown(r.operator),
        )
    return table
