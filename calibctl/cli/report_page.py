"""calibctl report: one calibration version as a self-contained HTML page."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.render import emit_json, stdout


def report(
    ctx: typer.Context,
    ref: Annotated[
        str | None,
        typer.Argument(
            metavar="SERIAL[@N]", help="Serial, optionally @version (default: active).", show_default=False
        ),
    ] = None,
    rig: Annotated[
        str | None,
        typer.Option(
            "--rig",
            metavar="RIG[@N]",
            show_default=False,
            help="Report a rig calibration instead (default: its active version).",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help="HTML file to write (default SERIAL-vN-report.html here).",
            show_default=False,
        ),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing --output file.")] = False,
    json_output: Annotated[bool, typer.Option("--json", help="Print where it was written as JSON.")] = False,
) -> None:
    """Write the calibration report: verdict, lint, parameters with sigma, coverage, residuals, per-view
    and held-out RMS, projection uncertainty, distortion, the diff against the previous accepted version, the
    robots' health trends (when they reported), gates and provenance. Works after images are pruned.

    With --rig: baselines with sigma, the T_root_cam tree, held-out epipolar RMS and vertical disparity,
    loop closure, the members' verdicts linked to their own reports, and for a LiDAR edge T_lidar_cam with
    sigma, gates, held-out figures and the sweep drawn over its image (when the solve's files are unchanged).

    Example: calibctl report CAM-0042@3 -o cam-0042-v3.html
    """
    from calibctl.errors import UsageError

    if (ref is None) == (rig is None):
        raise UsageError(
            "report needs one of SERIAL[@N] or --rig RIG[@N]",
            "e.g. calibctl report CAM-0042, or calibctl report --rig stereo-front",
        )
    if rig is not None:
        from calibctl.workflows.rig import report_rig

        rig_path, rig_data = report_rig.write_rig_report(state(ctx).settings(), rig, out, force=force)
        cal = rig_data.calibration
        if wants_json(ctx, json_output):
            emit_json(
                {
                    "ref": f"{cal.rig}@{cal.version}",
                    "status": cal.status,
                    "path": str(rig_path),
                    "bytes": rig_path.stat().st_size,
                }
            )
            return
        stdout.print(f"rig {cal.rig}@{cal.version} ({cal.status}): report written to {rig_path}")
        return
    from calibctl.workflows.fleet import report_sections

    assert ref is not None
    path, data = report_sections.write_report(state(ctx).settings(), ref, out, force=force)
    if wants_json(ctx, json_output):
        emit_json(
            {
                "ref": data.artifact.ref,
                "status": data.artifact.status,
                "path": str(path),
                "bytes": path.stat().st_size,
            }
        )
        return
    stdout.print(f"{data.artifact.ref} ({data.artifact.status}): report written to {path}")


def register(app: typer.Typer) -> None:
    app.command("report")(report)
