"""calibctl solve: stored corners -> the serial's next calibration version, with its verdict."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import OverrideGaugeOption
from calibctl.cli.render import emit_json, stdout
from calibctl.cli.report import print_calibration
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.errors import EXIT_VERDICT_FAIL, UsageError

if TYPE_CHECKING:
    from calibctl.workflows.camera import solve as solve_workflow

ModelOption = Annotated[
    str,
    typer.Option(
        "--model",
        help="k1k2 (default: FIX_K3|ZERO_TANGENT_DIST|FIX_ASPECT_RATIO), k1k2k3, k1k2p1p2k3, rational, "
        "opencv-default (flags 0), fisheye (equidistant k1..k4, cv2.fisheye / ROS equidistant; "
        "self-initialising), "
        "or auto (enable a coefficient, or switch to fisheye, only if fit RMS improves >= 10% "
        "and the held-out outer ring does not worsen).",
    ),
]

ActivateOption = Annotated[
    bool, typer.Option("--activate/--no-activate", help="Make an accepted result active.")
]
DropOutliersOption = Annotated[
    bool,
    typer.Option(
        "--drop-outliers", help="Re-solve without outlier views (implausible corners are always removed)."
    ),
]


MAX_OUTLIER_ROWS = 10  # kept outlier corners listed; --json has them all


def render_outlier_corners(corners: list[dict[str, float | int | str]]) -> None:
    """The outlier corners a solve kept, the first MAX_OUTLIER_ROWS, then how many more."""
    for c in corners[:MAX_OUTLIER_ROWS]:
        stdout.print(
            f"  outlier corner kept (its view has too few corners to lose it): {c['view']} "
            f"id {c['corner_id']} residual {float(c['residual_px']):.2f} px"
        )
    if len(corners) > MAX_OUTLIER_ROWS:
        stdout.print(f"  ... {len(corners) - MAX_OUTLIER_ROWS} more outlier corners kept (see --json)")


def render_outcome(outcome: solve_workflow.SolveOutcome, as_json: bool) -> None:
    art = outcome.artifact
    if as_json:
        emit_json(art)
    else:
        print_calibration(art, active=outcome.active)
        if outcome.report_path is not None:
            stdout.print(f"  report: {outcome.report_path}")
        render_outlier_corners(outcome.outlier_corners)
        if art.status == "accepted":
            state_word = "active" if outcome.active else "stored, not activated (--no-activate)"
            stdout.print(f"[green]{art.serial}@{art.version} accepted[/green] and {state_word}")
        else:
            stdout.print(
                f"[red]{art.serial}@{art.version} rejected[/red]: stored for the record, never active"
            )
    if art.status != "accepted":
        raise typer.Exit(EXIT_VERDICT_FAIL)


def solve(
    ctx: typer.Context,
    session_id: Annotated[
        str | None, typer.Argument(metavar="[SESSION_ID]", help="Capture session to solve.")
    ] = None,
    serial: Annotated[
        str | None, typer.Option("--serial", help="Solve this serial's latest accepted session.")
    ] = None,
    model: ModelOption = DEFAULT_MODEL,
    activate: ActivateOption = True,
    drop_outliers: DropOutliersOption = False,
    override_gauge: OverrideGaugeOption = None,
    json_output: Annotated[bool, typer.Option("--json", help="Print the artifact as JSON.")] = False,
    rig: Annotated[
        str | None,
        typer.Option(
            "--rig",
            help="Solve this rig instead (SESSION_ID is then a rig session; same as `calibctl rig solve`).",
            show_default=False,
        ),
    ] = None,
    refine_intrinsics: Annotated[
        bool, typer.Option("--refine-intrinsics", help="With --rig: refine the members' intrinsics jointly.")
    ] = False,
    report_dir: Annotated[
        Path | None,
        typer.Option(
            "--report",
            metavar="DIR",
            help="Also write the HTML report "
            "(SERIAL-vN-report.html) of the new version into DIR; a "
            "page of that name already there is refused before "
            "anything is stored.",
            show_default=False,
        ),
    ] = None,
    image_circle: Annotated[
        str | None,
        typer.Option(
            "--image-circle",
            metavar="CX,CY,R",
            show_default=False,
            help="The image circle of a circular fisheye, pixels: recorded with the calibration, the "
            "fold-over check "
            "stops at it (default: the one the capture found or was given).",
        ),
    ] = None,
) -> None:
    """Solve intrinsics from a capture session; exit 0 accepted, 1 rejected by lint, 2 could not solve."""
    from calibctl.workflows.camera import solve as solve_workflow
    from calibctl.workflows.camera.image_circles import parse_image_circle

    if rig is not None:
        from calibctl.cli.rig import solve as solve_rig

        if report_dir is not None:
            raise UsageError(
                "--report is not available with --rig yet", "run `calibctl solve --rig` without it"
            )
        # a rig solve keeps its members' calibrations: what shapes one camera's solve would be dropped
        # silently
        one_camera = {
            "--serial": serial,
            "--model": model if _given(ctx, "model") else None,
            "--drop-outliers": drop_outliers or None,
            "--image-circle": image_circle,
            "--override-gauge": override_gauge,
        }
        given = [flag for flag, value in one_camera.items() if value is not None]
        if given:
            raise UsageError(
                f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to one camera, not to a "
                "rig (--rig)",
                "solve that camera's own session (`calibctl solve SESSION_ID` or "
                "--serial); the rig solve uses the members' active calibrations",
            )
        solve_rig(ctx, rig, session_id, refine_intrinsics, activate, json_output)
        return
    if refine_intrinsics:
        raise UsageError(
            "--refine-intrinsics applies to a rig solve (--rig RIG)",
            "leave it out to solve one camera's intrinsics",
        )

    request = solve_workflow.SolveRequest(
        session_id=session_id,
        serial=serial,
        model=model,
        activate=activate,
        drop_outliers=drop_outliers,
        report_dir=report_dir,
        image_circle=parse_image_circle(image_circle),
        override_gauge=override_gauge,
    )
    outcome = solve_workflow.solve(state(ctx).settings(), request)
    render_outcome(outcome, wants_json(ctx, json_output))


def _given(ctx: typer.Context, name: str) -> bool:
    """True when the option ``name`` was given (on the command line or in the environment), not defaulted."""
    source = ctx.get_parameter_source(name)
    return source is not None and source.name != "DEFAULT"


def register(app: typer.Typer) -> None:
    app.command("solve")(solve)
