"""calibctl rig solve-folders: stereo and multi-camera extrinsics from per-camera photo folders."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from calibctl.cli.context import wants_json
from calibctl.cli.render import emit_json, stdout
from calibctl.errors import EXIT_VERDICT_FAIL, UsageError

rig_app = typer.Typer(
    name="rig",
    help="Camera rigs: extrinsics of 2+ cameras as a tree from one root, with one-sigma per edge.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


def say(line: str) -> None:
    stdout.print(line, soft_wrap=True, markup=False, highlight=False)


def render_run(doc: dict[str, Any]) -> None:
    """Human report of ``rig_folders.run_json``."""
    unmatched = doc["unmatched"]
    say(f"rig {' '.join(doc['cameras'])}: {doc['frames']} synchronised frames, {len(unmatched)} unmatched photo(s)")
    for u in unmatched[:10]:
        say(f"  unmatched {u['camera']} {u['file']}: {u['reason']}")
    for name, counts in doc["images"].items():
        say(f"  {name}: " + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
    say("  shared views: " + ", ".join(f"{p} {n}" for p, n in doc["shared_views"].items()))
    g = doc["gate"]
    say(f"  gate rig-connected {'pass' if g['passed'] else 'FAIL'}  {g['message']}"
        + (f" -> {g['hint']}" if g["hint"] else ""))
    if "tree" not in doc:
        return
    say(f"tree from {doc['root']} ({doc['solver']}):")
    for e in doc["tree"]:
        say(f"  T_{e['parent']}_{e['child']}: |t| = {e['translation_mm']:.3f} +/- {e['sigma_translation_mm']:.3f} mm, "
            f"rotation {e['rotation_deg']:.4f} +/- {e['sigma_rotation_deg']:.4f} deg")
    held = doc.get("held_out", {})
    for name, rms in doc["fit_rms_px"].items():
        say(f"  {name}: RMS fit {rms:.3f} px / held-out {held.get('rms_px', {}).get(name, float('nan')):.3f} px "
            f"({held.get('folds', 0)}-fold)")
    for p in doc["pairs"]:
        line = (f"  pair {p['pair']}: baseline {p['baseline_mm']:.3f} +/- {p['sigma_baseline_mm']:.3f} mm, "
                f"{p['shared_views']} shared views")
        if "epipolar_rms_px" in p:
            line += (f"; held-out epipolar RMS {p['epipolar_rms_px']:.3f} px (max {p['epipolar_max_px']:.3f}), "
                     f"rectified rows RMS {p['rectified_rms_px']:.3f} px")
        say(line)
    for lc in doc["loops"]:
        say(f"  loop {'-'.join(lc['cycle'])}: {lc['rotation_deg']:.4f} deg (sigma {lc['sigma_rotation_deg']:.4f}), "
            f"{lc['translation_mm']:.3f} mm (sigma {lc['sigma_translation_mm']:.3f}), Mahalanobis {lc['mahalanobis']:.2f}")


@rig_app.command("solve-folders")
def solve_folders(
    ctx: typer.Context,
    source: Annotated[list[str], typer.Option("--source", help="SERIAL=FOLDER, one per camera; the first is the root "
                                              "unless --root. Photos pair up by the last number in their names.")],
    cols: Annotated[int, typer.Option("--cols", help="Chessboard inner corners per row.")],
    rows: Annotated[int, typer.Option("--rows", help="Chessboard inner corners per column.")],
    square_mm: Annotated[float, typer.Option("--square-mm", help="Square edge, millimetres (measured, ideally).")],
    root: Annotated[str | None, typer.Option("--root", help="Root camera of the tree.", show_default=False)] = None,
    model: Annotated[str, typer.Option("--model", help="Each camera's intrinsic model (core solve models).")] = "k1k2",
    refine_intrinsics: Annotated[bool, typer.Option("--refine-intrinsics", help="Refine intrinsics jointly.")] = False,
    min_shared_views: Annotated[int, typer.Option("--min-shared-views", help="Rig gate: frames per linking pair.")] = 5,
    export_dir: Annotated[Path | None, typer.Option("--export-dir", help="Write the robot exports here.",
                                                    show_default=False)] = None,
    json_output: Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")] = False,
) -> None:
    """Solve a rig from per-camera folders (no store): exit 0 solved, 1 rig gate failed, 2 could not solve.

    Each camera is first calibrated on its own photos; then the extrinsics (cv2.stereoCalibrateExtended
    for two cameras, calibctl's joint LM for more), their one-sigma, k-fold held-out epipolar error and
    rectified rows per pair, and loop closure for three or more cameras.
    """
    from calibctl.core.board_spec import BoardSpec
    from calibctl.workflows import rig_folders

    sources = rig_folders.parse_sources(source)
    if root is not None:
        if root not in sources:
            raise UsageError(f"--root {root} is not one of the cameras ({', '.join(sources)})")
        sources = {root: sources[root], **{k: v for k, v in sources.items() if k != root}}
    try:
        spec = BoardSpec.chessboard(cols, rows, square_mm / 1e3)
    except ValueError as exc:
        raise UsageError(f"bad board: {exc}") from exc
    run = rig_folders.solve_rig_folders(sources, spec, model, None, refine_intrinsics, min_shared_views)
    doc = rig_folders.run_json(run)
    exports: list[str] = []
    if export_dir is not None and run.solution is not None:
        from calibctl.workflows.rig_exports import write_exports

        exports = [str(p) for p in write_exports(run.solution, export_dir)]
        doc["exports"] = exports
    if wants_json(ctx, json_output):
        emit_json(doc)
    else:
        render_run(doc)
        for path in exports:
            say(f"  wrote {path}")
    if not run.gate.passed:
        raise typer.Exit(EXIT_VERDICT_FAIL)


def register(app: typer.Typer) -> None:
    """Add the ``rig`` command group to the root app."""
    app.add_typer(rig_app, name="rig")
