"""calibctl demo: the main job end to end on a synthetic camera, no camera or arguments needed."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from calibctl.cli.context import state
from calibctl.cli.render import stdout
from calibctl.cli.report import history_table, print_calibration, print_findings, print_gates

if TYPE_CHECKING:
    from calibctl.workflows.camera import demo as demo_workflow


def _render(step: demo_workflow.DemoStep) -> None:
    stdout.rule(step.title, align="left")
    p = step.payload
    if step.kind == "board":
        m = p.measurement
        stdout.print(
            f"{p.ref}: {p.kind} {p.cols}x{p.rows} inner corners, square {m.square_size_m * 1000:.3f} mm "
            f"+/- {m.uncertainty_m * 1000:.3f} mm ({m.instrument}, {m.measured_by}, {m.measured_on})"
        )
    elif step.kind == "capture":
        s = p.session
        counts: dict[str, int] = {}
        for o in s.outcomes:
            counts[o.status] = counts.get(o.status, 0) + 1
        summary = ", ".join(f"{n} {k}" for k, n in sorted(counts.items()))
        verdict = "[green]accepted[/green]" if s.status == "accepted" else "[red]rejected[/red] (exit 1)"
        stdout.print(
            f"session {s.session_id}: {len(s.outcomes)} images ({summary}); {len(s.views)} views; {verdict}"
        )
        print_gates(s.gates)
    elif step.kind == "solve":
        print_calibration(p.artifact, active=p.active)
    elif step.kind == "lint":
        for r in p:
            stdout.print(f"{r.source}: {'[red]FAIL[/red]' if r.failed else '[green]pass[/green]'}")
            print_findings(r.findings)
    elif step.kind == "history":
        stdout.print(history_table(p.versions, p.serial))
    elif step.kind == "export":
        stdout.print(p, markup=False, end="", soft_wrap=True)  # a file: never re-wrapped
    elif step.kind == "truth":
        z_fx = f" = {p.z_fx:+.2f} sigma" if p.z_fx is not None else ""
        z_cx = f" = {p.z_cx:+.2f} sigma" if p.z_cx is not None else ""
        stdout.print(
            f"fx: true {p.fx_true:.2f}, solved {p.fx_est:.2f}, error {p.fx_est - p.fx_true:+.2f} px{z_fx}"
        )
        stdout.print(
            f"cx: true {p.cx_true:.2f}, solved {p.cx_est:.2f}, error {p.cx_est - p.cx_true:+.2f} px{z_cx}"
        )


def demo(
    ctx: typer.Context,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="Folder for the demo's images, store and export [default: demo-out].",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Render a synthetic camera, register a measured board, capture, solve, lint, show history, export ROS
    YAML."""
    from calibctl.workflows.camera import demo as demo_workflow

    st = state(ctx)
    out = out or demo_workflow.DEMO_DIR
    demo_workflow.prepare_dir(out)
    db = st.db or f"sqlite:///{out / 'calibctl-demo.db'}"
    settings = st.settings(station="demo-station", operator="demo-operator").model_copy(update={"db_url": db})
    stdout.print(f"calibctl demo: store {db}, images in {out}/")
    solved = demo_workflow.run_demo(settings, out, _render)
    stdout.rule()
    stdout.print(
        f"done: {solved.artifact.serial}@{solved.artifact.version} {solved.artifact.status}"
        f"{' and active' if solved.active else ''}. Try: calibctl --db {db} show {solved.artifact.serial}"
    )


def register(app: typer.Typer) -> None:
    app.command("demo")(demo)
