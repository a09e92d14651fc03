"""calibctl diff: is one camera calibration different from another beyond their uncertainties?"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.render import emit_json, fmt_px, say, shown

if TYPE_CHECKING:
    from calibctl.core.compare.projection_diff import DiffField
    from calibctl.workflows.compare.diff import CameraDiff
    from calibctl.workflows.compare.rig_diff import RigDiff


def _field_line(name: str, f: DiffField) -> str:
    p = f.percentiles_px
    line = (
        f"  {name:<16} |d| p50 {fmt_px(p['p50'])}  p90 {fmt_px(p['p90'])}  p99 {fmt_px(p['p99'])}  "
        f"max {fmt_px(p['max'])} px"
    )
    if f.sigma_px is not None and f.test is not None:
        t = f.test
        line += (
            f"; expected sigma {fmt_px(float(f.sigma_px.min()))}-{fmt_px(float(f.sigma_px.max()))} px; "
            f"chi2 {t.statistic:.1f} vs {t.threshold:.1f} ({t.dof} dof, p = {t.p_value:.2g})"
        )
    return line


def print_diff(d: CameraDiff) -> None:
    r = d.result
    rng = "rays (infinite range)" if math.isinf(r.range_m) else f"points at {r.range_m:g} m"
    say(
        f"diff {shown(d.a.ref)} ({d.a.model.name}, {d.a.status}) -> {shown(d.b.ref)} ({d.b.model.name}, "
        f"{d.b.status}): {d.verdict.upper()}"
    )
    say(
        f"  {len(r.pixels_px)} samples over {d.a.image_size[0]}x{d.a.image_size[1]} "
        f"({r.grid[0]}x{r.grid[1]} grid, "
        f"{r.dropped} outside a model), {rng}"
    )
    say(_field_line("as stored", r.raw))
    say(_field_line(f"rotation {r.rotation_fit_deg:.3f} deg", r.fit))
    for reason in r.reasons:
        say(f"  -> {reason}")
    for note in d.notes:
        say(f"  note: {note}")
    if d.map_path is not None:
        say(f"  map: {d.map_path}")


def print_rig_diff(d: RigDiff) -> None:
    say(f"diff rig {shown(d.ref_a)} ({d.a.status}) -> {shown(d.ref_b)} ({d.b.status}): {d.verdict.upper()}")
    for p in [*d.pairs, *d.edges]:
        say(
            f"  {shown(p.a)} -> {shown(p.b)}: rotation {p.rotation_deg:.4f} +/- {p.sigma_rotation_deg:.4f} "
            "deg, "
            f"translation {p.translation_mm:.3f} +/- {p.sigma_translation_mm:.3f} mm, chi2 {p.chi2:.1f} vs "
            f"{p.threshold:.1f} (6 dof, p = {p.p_value:.2g}) {'DIFFERENT' if p.significant else 'same'}"
        )
        if p.depth:
            say(
                f"    baseline {p.baseline_a_mm:.3f} -> {p.baseline_b_mm:.3f} mm "
                f"({p.baseline_change_mm:+.3f} +/- "
                f"{p.sigma_baseline_change_mm:.3f} mm); depth error with the old one: "
                + ", ".join(
                    f"{z.error_m * 1e3:+.1f} +/- {z.sigma_m * 1e3:.1f} mm at {z.depth_m:g} m" for z in p.depth
                )
            )
    for note in d.notes:
        say(f"  note: {shown(note)}")


def diff(
    ctx: typer.Context,
    ref_a: Annotated[
        str, typer.Argument(metavar="A", help="SERIAL[@N]: the reference (default version: active).")
    ],
    ref_b: Annotated[str, typer.Argument(metavar="B", help="SERIAL[@N]: the one compared against A.")],
    rig: Annotated[
        bool, typer.Option("--rig", help="A and B are rig versions (RIG[@N]): compare their extrinsics.")
    ] = False,
    range_m: Annotated[
        float,
        typer.Option(
            "--range-m",
            help="Distance of the compared points along A's rays, "
            "metres (default: infinity, i.e. rays; a finite range also fits "
            "a translation, as mrcal).",
            show_default=False,
        ),
    ] = math.inf,
    scale: Annotated[
        float | None,
        typer.Option(
            "--scale",
            help="B's pixels times SCALE are A's: needed when the image sizes differ.",
            show_default=False,
        ),
    ] = None,
    grid: Annotated[
        str, typer.Option("--grid", metavar="COLSxROWS", help="Sample grid over A's imager.")
    ] = "40x30",
    map_path: Annotated[
        Path | None,
        typer.Option("--map", help="Write an HTML page of SVG maps of the difference.", show_default=False),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing --map file.")] = False,
    json_output: Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")] = False,
) -> None:
    """Compare two camera calibrations by their projection difference over the imager.

    Each sample pixel is unprojected with A and projected with B, as stored and after the rotation that
    best aligns the two (mrcal's show-projection-diff); the difference is tested against its expected
    spread from both stored covariances (chi-square, at most 1 % false flags for an unchanged camera).
    With --rig: each camera pair's rotation, translation and baseline change with sigma (chi-square on 6
    dof per pair, Bonferroni over the pairs) and the depth error the old extrinsics would make at 1, 2, 5,
    10 m; hand-eye edges' rotation and translation change with sigma.
    Exit 0: same within noise; 1: significantly different; 2: cannot compare (unknown ref, same ref,
    different image sizes without --scale, or a calibration without a covariance: numbers, no verdict).
    """
    from calibctl.errors import EXIT_CANNOT_RUN, UsageError, VerdictFailed
    from calibctl.workflows.compare import diff as diff_workflow

    try:
        cols, rows = (int(x) for x in grid.lower().split("x"))
    except ValueError:
        raise UsageError(f"--grid '{grid}' is not COLSxROWS", "e.g. --grid 40x30") from None
    if rig:
        from calibctl.workflows.compare import rig_diff

        camera_only = [
            name
            for name, used in (
                ("--range-m", not math.isinf(range_m)),
                ("--scale", scale is not None),
                ("--grid", grid != "40x30"),
                ("--map", map_path is not None),
            )
            if used
        ]
        if camera_only:
            raise UsageError(
                f"{', '.join(camera_only)} applies to camera diffs, not to --rig",
                "drop it, or diff the member cameras: calibctl diff SERIAL@N SERIAL@M",
            )

        rig_result = rig_diff.diff_rigs(state(ctx).settings(), ref_a, ref_b)
        if wants_json(ctx, json_output):
            emit_json(rig_result.as_json())
        else:
            print_rig_diff(rig_result)
        if rig_result.verdict == "different":
            raise typer.Exit(VerdictFailed.exit_code)
        return
    request = diff_workflow.DiffRequest(ref_a, ref_b, range_m, scale, (cols, rows), map_path, force)
    result = diff_workflow.diff_cameras(state(ctx).settings(), request)
    if wants_json(ctx, json_output):
        emit_json(result.as_json())
    else:
        print_diff(result)
    if result.verdict == "unknown":
        print(
            "Error: no verdict: "
            + ", ".join(
                f"{s.ref} stores no covariance" for s in (result.a, result.b) if s.stdev.covariance is None
            ),
            file=sys.stderr,
        )
        print(
            "Hint: re-solve it with this calibctl (it stores the covariance), then diff again",
            file=sys.stderr,
        )
        raise typer.Exit(EXIT_CANNOT_RUN)
    if result.verdict == "different":
        raise typer.Exit(VerdictFailed.exit_code)


def register(app: typer.Typer) -> None:
    app.command("diff")(diff)
