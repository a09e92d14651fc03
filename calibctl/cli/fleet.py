"""calibctl fleet add | assign | status: robots, the calibration version each runs, and where they stand."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.render import emit_json, say, shown, stderr
from calibctl.errors import EXIT_VERDICT_FAIL

if TYPE_CHECKING:
    from calibctl.workflows.fleet.rollouts import Rollout
    from calibctl.workflows.fleet.trends import Trends

JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
ReasonOption = Annotated[
    str, typer.Option("--reason", help="Why (kept in the fleet's log).", show_default=False)
]

MAX_SHOWN_LINES = 20  # refused lines named per file on stderr; --json carries every one
MAX_SHOWN_DIFFS = 10  # a rollout's diffs listed one a line; above, counted by verdict

fleet_app = typer.Typer(
    name="fleet",
    help="Robots, the calibration version each one runs, and where that stands against the active versions.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@fleet_app.command("add")
def add(
    ctx: typer.Context,
    robot: Annotated[str, typer.Argument(help="Robot name (letters, digits, . _ : -).")],
    serial: Annotated[
        list[str] | None,
        typer.Option("--serial", help="A camera serial it carries (repeatable).", show_default=False),
    ] = None,
    rig: Annotated[
        list[str] | None, typer.Option("--rig", help="A rig it carries (repeatable).", show_default=False)
    ] = None,
    reason: ReasonOption = "registered",
    json_output: JsonFlag = False,
) -> None:
    """Register a robot and the sensors it carries (once; the log keeps who, when and why)."""
    from calibctl.workflows.fleet import robots

    event = robots.add_robot(state(ctx).settings(), robot, serial or [], rig or [], reason)
    if wants_json(ctx, json_output):
        emit_json(event)
        return
    say(f"robot {shown(event.subject)} registered: {', '.join(map(shown, [*event.serials, *event.rigs]))}")


@fleet_app.command("assign")
def assign(
    ctx: typer.Context,
    robot: Annotated[str, typer.Argument(help="A registered robot.")],
    ref: Annotated[
        str, typer.Argument(metavar="SERIAL@N", help="The calibration version the robot now runs.")
    ],
    reason: ReasonOption = "",
    rig: Annotated[bool, typer.Option("--rig", help="REF is RIG@N, a rig's calibration version.")] = False,
    json_output: JsonFlag = False,
) -> None:
    """Record that a robot now runs SERIAL@N (or, with --rig, RIG@N): an accepted version it carries."""
    from calibctl.workflows.fleet import robots

    event = robots.assign(state(ctx).settings(), robot, ref, reason, rig=rig)
    if wants_json(ctx, json_output):
        emit_json(event)
        return
    what = shown(event.serial) if event.rig is None else f"rig {shown(event.rig)}"
    say(f"robot {shown(event.subject)} runs {what}@{event.version}")


@fleet_app.command("status")
def status(ctx: typer.Context, json_output: JsonFlag = False) -> None:
    """Every robot, its sensors and the version each runs: current, behind or ahead of the active one."""
    from calibctl.workflows.fleet import rollouts

    result, staged = rollouts.fleet_status(state(ctx).settings())
    if wants_json(ctx, json_output):
        emit_json({**result.as_json(), "rollouts": [r.as_json() for r in staged]})
        return
    for rollout in staged:
        _print_rollout(rollout)
    if not result.robots:
        say("no robots registered (calibctl fleet add ROBOT --serial SERIAL)")
        return
    for r in result.robots:
        say(shown(r.robot))
        for prefix, sensors in (("", r.sensors), ("rig ", r.rigs)):
            for s in sensors:
                running = "-" if s.running is None else f"@{s.running}"
                active = "-" if s.active is None else f"@{s.active}"
                say(f"  {prefix + shown(s.serial):<20} runs {running:<6} active {active:<6} {s.state}")


@fleet_app.command("ingest")
def ingest(
    ctx: typer.Context,
    files: Annotated[
        list[Path], typer.Argument(metavar="FILE...", help="JSON-lines files, one health report a line.")
    ],
    json_output: JsonFlag = False,
) -> None:
    """Store the health reports robots send, all or nothing per file.

    Exit 1 when a file had a refused line (malformed, from the future, a serial its robot does not carry, a
    duplicate source id): that file wrote nothing, each refused line is named; the other files are stored."""
    from calibctl.workflows.fleet import health

    results = health.ingest(state(ctx).settings(), files)
    refused = [r for r in results if r.refused]
    if wants_json(ctx, json_output):
        emit_json({"stored": sum(r.stored for r in results), "files": [r.as_json() for r in results]})
    else:
        for r in results:
            say(
                f"{shown(r.path)}: "
                + (
                    f"{r.stored} report(s) stored"
                    if not r.refused
                    else f"refused, nothing stored ({len(r.refused)} bad line(s))"
                )
            )
    for r in refused:
        for line, why in r.refused[:MAX_SHOWN_LINES]:
            stderr.print(
                f"{shown(r.path)}:{line}: {shown(why)}", soft_wrap=True, markup=False, highlight=False
            )
        if len(r.refused) > MAX_SHOWN_LINES:
            stderr.print(
                f"{shown(r.path)}: {len(r.refused) - MAX_SHOWN_LINES} more refused line(s) (--json lists "
                "all)",
                soft_wrap=True,
                markup=False,
                highlight=False,
            )
    if refused:
        raise typer.Exit(EXIT_VERDICT_FAIL)


def _print_trends(t: Trends) -> None:
    say(f"{shown(t.serial)}: " + ", ".join(f"{n} {k}" for k, n in t.counts.items()))
    s = t.rms_vs_temperature_px_per_c
    if s is not None:
        say(f"  RMS vs temperature: {s.slope:+.4f} +- {s.sigma:.4f} px/degC (n {s.n})")
    for b in t.rms_by_temperature:
        say(
            f"    {b['from_c']:>6.0f}..{b['to_c']:<4.0f} degC  n {b['n']:<5} RMS mean {b['mean']:.3f} px  "
            f"max {b['max']:.3f} px"
        )
    if t.check_verdicts:
        say("  checks: " + ", ".join(f"{n} {v}" for v, n in t.check_verdicts.items()))
    d = t.td_drift_ppm
    if d is not None:
        say(f"  td vs time: {d.slope:+.2f} +- {d.sigma:.2f} ppm over {t.td_span_days:.1f} days (n {d.n})")
    for b in t.td_by_temperature:
        say(f"    {b['from_c']:>6.0f}..{b['to_c']:<4.0f} degC  n {b['n']:<5} td mean {b['mean']:+.3f} ms")
    if t.gauge is not None:
        g = t.gauge
        say(f"  gauge ratio: median {g['median']:.4f}, p05..p95 {g['p05']:.4f}..{g['p95']:.4f} (n {g['n']})")
    if t.triage_verdicts:
        say("  triage: " + ", ".join(f"{n} {v}" for v, n in t.triage_verdicts.items()))
    f = t.fleet
    if f is not None:
        ratio = "-" if f["max_over_min"] is None else f"{f['max_over_min']:.2f}x"
        say(
            f"  fleet (last {f.get('window_days', '-')} days): this camera's mean RMS "
            f"{f['this_mean_rms_px']:.3f} px, rank {f['rank']} of {f['serials']} "
            f"(others' median {f['others_median_rms_px']:.3f} px, min {f['min_rms_px']:.3f}, max "
            f"{f['max_rms_px']:.3f} "
            f"px, max/min {ratio})"
        )
    for finding in t.findings:
        say(f"  ! {finding}")


@fleet_app.command("trends")
def trends(
    ctx: typer.Context,
    serial: Annotated[str, typer.Argument(help="A camera serial with health reports.")],
    json_output: JsonFlag = False,
) -> None:
    """A serial's health as conditionals: RMS vs temperature, td drift in ppm, gauge, its RMS against the
    fleet's."""
    from calibctl.workflows.fleet import health

    t = health.trends(state(ctx).settings(), serial)
    if wants_json(ctx, json_output):
        emit_json(t.as_json())
    else:
        _print_trends(t)


rollout_app = typer.Typer(
    name="rollout",
    help="A calibration change rolled out like a deploy: canary robots, a health gate, promote or roll back.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
fleet_app.add_typer(rollout_app, name="rollout")


def _render_rollout(ctx: typer.Context, json_output: bool, r: Rollout) -> None:
    """What start, promote and rollback print: the rollout as JSON, or its lines."""
    if wants_json(ctx, json_output):
        emit_json(r.as_json())
    else:
        _print_rollout(r)


def _print_rollout(r: Rollout) -> None:
    from calibctl.store.fleet_ledger import ref

    closed = f" ({r.closed})" if r.closed else ""
    say(f"rollout {shown(r.name)}{closed}: " + ", ".join(shown(ref(t, v)) for t, v in r.targets.items()))
    for robot, st in sorted(r.state.items()):
        why = "; ".join([*r.failing.get(robot, []), *(f"no report on {t}" for t in r.waiting.get(robot, []))])
        say(
            f"  {shown(robot):<20} "
            f"{st}{' (canary)' if robot in r.start.canary else ''}{f': {shown(why)}' if why else ''}"
        )
    diffs = r.diffs
    if len(diffs) > MAX_SHOWN_DIFFS:
        verdicts = [d.verdict for d in diffs.values()]
        say(
            "  diffs: "
            + ", ".join(f"{verdicts.count(v)} {v}" for v in sorted(set(verdicts)))
            + " (--json lists each)"
        )
        diffs = {}
    for t, d in diffs.items():
        numbers = (
            f", p50 {d.p50_px:.2f} px, max {d.max_px:.2f} px"
            if d.p50_px is not None and d.max_px is not None
            else f" ({shown(d.why)})"
            if d.why
            else ""
        )
        say(f"  diff {shown(ref(t, d.previous))} -> @{r.targets[t]}: {d.verdict}{numbers}")
    if r.promote is not None:
        say(
            f"  promoted on {len(r.promote.gate)} health input(s), recorded with their sha256 in the "
            "promote event"
        )


@rollout_app.command("start")
def rollout_start(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(help="Rollout name (letters, digits, . _ : -).")],
    target: Annotated[
        list[str] | None,
        typer.Option(
            "--target", metavar="SERIAL@N", help="A new camera version (repeatable).", show_default=False
        ),
    ] = None,
    rig_target: Annotated[
        list[str] | None,
        typer.Option(
            "--rig-target", metavar="RIG@N", help="A new rig version (repeatable).", show_default=False
        ),
    ] = None,
    canary: Annotated[
        list[str] | None,
        typer.Option("--canary", metavar="ROBOT", help="A canary robot (repeatable).", show_default=False),
    ] = None,
    reason: ReasonOption = "",
    json_output: JsonFlag = False,
) -> None:
    """Start a rollout: the canary robots run the new versions now, the rest wait for promote."""
    from calibctl.workflows.fleet import rollouts

    r = rollouts.start(state(ctx).settings(), name, target or [], canary or [], reason, rig_target or [])
    _render_rollout(ctx, json_output, r)


@rollout_app.command("promote")
def rollout_promote(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(help="The rollout.")],
    reason: ReasonOption = "",
    json_output: JsonFlag = False,
) -> None:
    """Promote to the rest of the fleet once every canary robot reports passing checks of the new version.

    The gate reads the canary robots' `calibctl check` events and their ingested health reports (check, gauge,
    triage) since the start; the promote records them (with their sha256) and each target's diff. Rig targets
    become their rigs' active versions. Exit 1 (held, nothing promoted) when a canary reports a failing one;
    2 when one has not reported yet."""
    from calibctl.workflows.fleet import rollouts

    r = rollouts.promote(state(ctx).settings(), name, reason)
    _render_rollout(ctx, json_output, r)


@rollout_app.command("rollback")
def rollout_rollback(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(help="The rollout.")],
    reason: ReasonOption = "",
    json_output: JsonFlag = False,
) -> None:
    """Put every robot the rollout touched back on the version it ran before, in one transaction."""
    from calibctl.workflows.fleet import rollouts

    r = rollouts.rollback(state(ctx).settings(), name, reason)
    _render_rollout(ctx, json_output, r)


def register(app: typer.Typer) -> None:
    app.add_typer(fleet_app, name="fleet")
