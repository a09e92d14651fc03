"""calibctl fleet add | assign | status: robots, the calibration version each runs, and where they stand."""

from __future__ import annotations

from typing import Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.render import emit_json, shown, stdout

JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
ReasonOption = Annotated[str, typer.Option("--reason", help="Why (kept in the fleet's log).", show_default=False)]

fleet_app = typer.Typer(
    name="fleet",
    help="Robots, the calibration version each one runs, and where that stands against the active versions.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


def _say(line: str) -> None:
    stdout.print(line, soft_wrap=True, markup=False, highlight=False)


@fleet_app.command("add")
def add(
    ctx: typer.Context,
    robot: Annotated[str, typer.Argument(help="Robot name (letters, digits, . _ : -).")],
    serial: Annotated[list[str] | None, typer.Option("--serial", help="A camera serial it carries (repeatable).",
                                                     show_default=False)] = None,
    rig: Annotated[list[str] | None, typer.Option("--rig", help="A rig it carries (repeatable).", show_default=False)] = None,
    reason: ReasonOption = "registered",
    json_output: JsonFlag = False,
) -> None:
    """Register a robot and the sensors it carries (once; the log keeps who, when and why)."""
    from calibctl.workflows.fleet import robots

    event = robots.add_robot(state(ctx).settings(), robot, serial or [], rig or [], reason)
    if wants_json(ctx, json_output):
        emit_json(event)
        return
    _say(f"robot {shown(event.subject)} registered: {', '.join(map(shown, [*event.serials, *event.rigs]))}")


@fleet_app.command("assign")
def assign(
    ctx: typer.Context,
    robot: Annotated[str, typer.Argument(help="A registered robot.")],
    ref: Annotated[str, typer.Argument(metavar="SERIAL@N", help="The calibration version the robot now runs.")],
    reason: ReasonOption = "",
    json_output: JsonFlag = False,
) -> None:
    """Record that a robot now runs SERIAL@N (an accepted version of a serial it carries)."""
    from calibctl.workflows.fleet import robots

    event = robots.assign(state(ctx).settings(), robot, ref, reason)
    if wants_json(ctx, json_output):
        emit_json(event)
        return
    _say(f"robot {shown(event.subject)} runs {shown(event.serial)}@{event.version}")


@fleet_app.command("status")
def status(ctx: typer.Context, json_output: JsonFlag = False) -> None:
    """Every robot, its sensors and the version each runs: current, behind or ahead of the active one."""
    from calibctl.workflows.fleet import robots

    result = robots.status(state(ctx).settings())
    if wants_json(ctx, json_output):
        emit_json(result.as_json())
        return
    if not result.robots:
        _say("no robots registered (calibctl fleet add ROBOT --serial SERIAL)")
        return
    for r in result.robots:
        rigs = f"  rigs: {', '.join(map(shown, r.rigs))}" if r.rigs else ""
        _say(f"{shown(r.robot)}{rigs}")
        for s in r.sensors:
            running = "-" if s.running is None else f"@{s.running}"
            active = "-" if s.active is None else f"@{s.active}"
            _say(f"  {shown(s.serial):<20} runs {running:<6} active {active:<6} {s.state}")


def register(app: typer.Typer) -> None:
    app.add_typer(fleet_app, name="fleet")
