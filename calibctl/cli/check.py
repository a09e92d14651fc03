"""calibctl check: re-test a stored calibration on fresh board views (parse, call the workflow, render)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import JobsOption
from calibctl.cli.render import emit_json, say

if TYPE_CHECKING:
    from calibctl.artifacts.check import CheckEvent


def print_check(event: CheckEvent) -> None:
    verdict = "pass" if event.passed else "FAIL"
    say(
        f"check {event.check_id} of {event.serial}@{event.version}: {verdict}  "
        f"({len(event.views)} views of {event.images} images, {event.image_size[0]}x{event.image_size[1]})"
    )
    for r in event.regions:
        if r.tested:
            say(
                f"  {r.region:<9} RMS {r.check_rms_px:.3f} px vs held-out {r.reference_rms_px:.3f} px: "
                f"x{r.ratio:.2f} (limit x{r.limit:.2f}) {'pass' if r.passed else 'FAIL'}"
            )
    for p in event.shifts:
        amount = f"{p.shift * 100:+.3f} %" if p.parameter == "focal" else f"{p.shift:+.2f} px"
        say(
            f"  {p.parameter:<9} pull {amount} ({p.shift / p.sigma:+.1f} sigma, limit {p.z_limit:.1f}) "
            f"{'pass' if p.passed else 'FAIL'}"
        )
    if event.distance is not None:
        d = event.distance
        say(
            f"  distance  {d.recovered_m:.4f} m vs surveyed {d.reference_m:.4f} m: ratio {d.ratio:.4f} "
            f"(needs {d.ratio_limits[0]}-{d.ratio_limits[1]}) {'pass' if d.passed else 'FAIL'}"
        )
    elif not event.not_judged:
        say("  distance  not judged: no --reference-distance (the metric gauge, seed chapter 0)")
    for part in event.not_judged or []:
        say(f"  not judged: {part}")
    for reason in event.reasons:
        say(f"  -> {reason}")


def check(
    ctx: typer.Context,
    ref: Annotated[
        str, typer.Argument(metavar="SERIAL[@N]", help="Serial, optionally @version (default: active).")
    ],
    source: Annotated[
        str,
        typer.Option(
            "--source", help="A folder, quoted glob or list file of fresh board images.", show_default=False
        ),
    ],
    reference_distance: Annotated[
        str | None,
        typer.Option(
            "--reference-distance",
            metavar="D+-S",
            show_default=False,
            help="Surveyed camera-to-board-centre distance and one-sigma, metres (or mm suffix), e.g. "
            "0.600+-0.001.",
        ),
    ] = None,
    station: Annotated[
        str | None, typer.Option("--station", help="Station id (default from settings).")
    ] = None,
    operator: Annotated[str | None, typer.Option("--operator", help="Who runs the check.")] = None,
    jobs: JobsOption = None,
    json_output: Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")] = False,
) -> None:
    """Re-test the active (or @N) calibration on fresh board images, without re-solving it.

    Exit 0 when the fresh views agree with the stored model (and the surveyed distance), 1 when they
    do not (the check is stored either way, in the serial's history), 2 when the check could not run.
    Ten views with the board close (filling most of the frame) and tilted 20-35 deg in different
    directions catch a 0.5 % focal change or a 2 px principal-point shift (benchmarks/results/check.md).
    """
    from calibctl.errors import VerdictFailed
    from calibctl.workflows.camera import check as check_workflow
    from calibctl.workflows.camera.distance_gauge import parse_reference_distance

    distance = None if reference_distance is None else parse_reference_distance(reference_distance)
    settings = state(ctx).settings(station=station, operator=operator, jobs=jobs)
    event = check_workflow.check(settings, check_workflow.CheckRequest(ref, source, distance))
    if wants_json(ctx, json_output):
        emit_json(event)
    else:
        print_check(event)
    if not event.passed:
        raise typer.Exit(VerdictFailed.exit_code)


def register(app: typer.Typer) -> None:
    app.command("check")(check)
