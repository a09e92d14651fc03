"""calibctl handeye and synth-motions: parse, call one workflow, render (exit 1 when a gate rejects)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from calibctl.cli.context import state, wants_json
from calibctl.cli.render import emit_json, stdout
from calibctl.errors import EXIT_VERDICT_FAIL

JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
MAX_MOTION_ROWS = 30


def _render(outcome) -> None:
    r = outcome.result
    stdout.print(
        f"hand-eye {escape(r.parent_frame)} -> {escape(r.child_frame)} "
        f"from {escape(r.provenance.input_file)} "
        f"({r.provenance.input_shape}, {len(r.motions)} motions, method {r.method})"
    )
    for g in r.gates:
        stdout.print(f"  gate {g.gate:<18}{'pass' if g.passed else 'FAIL'}  {escape(g.message)}")
    for s in r.skipped:
        stdout.print(f"  skipped: {escape(s)}")
    if r.transform is not None:
        t, q = r.transform.translation_m, r.transform.rotation_wxyz
        u = r.uncertainty
        sig_t = ("", "", "") if u is None else tuple(f" +/- {v:.2f}" for v in u.sigma_translation_mm)
        sig_r = (
            ""
            if u is None
            else " (sigma about x, y, z: " + ", ".join(f"{v:.3f}" for v in u.sigma_rotation_deg) + " deg)"
        )
        stdout.print(f"T_{escape(r.parent_frame)}_{escape(r.child_frame)}:")
        stdout.print(
            "  translation "
            + ", ".join(f"{axis} {v * 1e3:+.2f}{s} mm" for axis, v, s in zip("xyz", t, sig_t, strict=True))
        )
        stdout.print(
            f"  rotation    quaternion wxyz ({q[0]:+.6f}, {q[1]:+.6f}, {q[2]:+.6f}, {q[3]:+.6f}){sig_r}"
        )
        if u is not None:
            stdout.print(
                f"  refined on {r.refinement}; residual RMS per component {u.residual_rotation_deg:.4f} deg, "
                f"{u.residual_translation_mm:.3f} mm"
            )
        if r.uncertainty_refused_reason:
            stdout.print(f"  no uncertainty: {escape(r.uncertainty_refused_reason)}")
    table = Table(
        "motion", "angle a deg", "angle b deg", "mismatch deg", "res rot deg", "res trans mm", "outlier"
    )
    for m in r.motions[:MAX_MOTION_ROWS]:
        table.add_row(
            escape(m.label),
            f"{m.angle_parent_deg:.2f}",
            f"{m.angle_child_deg:.2f}",
            f"{m.angle_mismatch_deg:+.3f}",
            "-" if m.residual_rotation_deg is None else f"{m.residual_rotation_deg:.4f}",
            "-" if m.residual_translation_mm is None else f"{m.residual_translation_mm:.2f}",
            "OUTLIER" if m.outlier else "",
        )
    stdout.print(table)
    if len(r.motions) > MAX_MOTION_ROWS:
        stdout.print(f"... {len(r.motions) - MAX_MOTION_ROWS} more motions (see --json)")
    if r.outlier_motions:
        stdout.print(f"outlier motions: {escape(', '.join(r.outlier_motions))}")
    for path in outcome.written:
        stdout.print(f"wrote {escape(path)}")
    for path in outcome.not_written:
        stdout.print(f"not written: {escape(path)}")
    if r.status == "accepted":
        stdout.print("Result: ACCEPTED")
    else:
        failed = [g.message for g in r.gates if not g.passed]
        stdout.print("Result: REJECTED (no transform reported): " + escape("; ".join(failed)))


def handeye(
    ctx: typer.Context,
    motions: Annotated[
        Path,
        typer.Argument(
            metavar="MOTIONS.csv",
            help="Synchronised poses or motions "
            "(docs/handeye.md); with --images: image + gripper pose per row, or a "
            "file without header of 16 numbers per line (row-major 4x4 "
            "T_base_gripper, metres; line i = i-th image by name).",
        ),
    ],
    from_frame: Annotated[str, typer.Option("--from", help="Frame A (tf parent): X = T_A_B.")],
    to_frame: Annotated[str, typer.Option("--to", help="Frame B (tf child).")],
    input_shape: Annotated[
        str, typer.Option("--input", help="poses (one pose per sensor per row) or motions.")
    ] = "poses",
    method: Annotated[
        str, typer.Option("--method", help="park (Park & Martin) or tsai (Tsai-Lenz).")
    ] = "park",
    max_skew_ms: Annotated[
        float, typer.Option("--max-skew-ms", min=0.0, help="Largest |a_t_s - b_t_s| in a row.")
    ] = 5.0,
    lever_arm_sigma_min: Annotated[
        float | None,
        typer.Option(
            "--lever-arm-sigma-min",
            min=1e-9,
            help="Gate on sigma_min of the stacked (R_A - I) (default 0.5).",
        ),
    ] = None,
    images: Annotated[
        Path | None, typer.Option("--images", help="Robot arm: folder of the board images.")
    ] = None,
    serial: Annotated[
        str | None, typer.Option("--serial", help="Robot arm: camera whose active calibration to use.")
    ] = None,
    board: Annotated[
        str | None, typer.Option("--board", help="Robot arm: NAME[@REV] (default: the calibration's).")
    ] = None,
    eye_to_hand: Annotated[
        bool,
        typer.Option(
            "--eye-to-hand/--eye-in-hand", help="Robot arm: camera fixed in the cell, or on the gripper."
        ),
    ] = False,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Write the result document (JSON).")] = None,
    tf_static: Annotated[
        Path | None, typer.Option("--tf-static", help="Write the edge as /tf_static YAML (accepted only).")
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing output files.")] = False,
    rig: Annotated[
        str | None,
        typer.Option(
            "--rig",
            help="Store the result as the rig's next version (edge "
            "FROM -> TO of its tree; rejected results never active).",
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Extrinsics from motion, A X = X B, gated on observability (exit 1 when a gate rejects)."""
    from calibctl.cli.stored_edge import stored_line, stored_summary
    from calibctl.workflows.handeye import handeye as wf
    from calibctl.workflows.handeye.handeye_run import run_handeye_command

    outcome = run_handeye_command(
        state(ctx).settings(),
        motions,
        from_frame,
        to_frame,
        rig=rig,
        images=images,
        serial=serial,
        board_ref=board,
        eye_to_hand=eye_to_hand,
        shape=input_shape,
        method=method,
        max_skew_s=max_skew_ms / 1e3,
        lever_arm_sigma_min=lever_arm_sigma_min,
        outputs=wf.Outputs(out, tf_static, force),
    )
    stored = outcome.stored
    if wants_json(ctx, json_output):
        emit_json(
            outcome.result
            if stored is None
            else {"result": outcome.result.model_dump(mode="json"), "stored": stored_summary(stored)}
        )
    else:
        _render(outcome)
        if stored is not None:
            stdout.print(escape(stored_line(stored)))
    if not outcome.accepted or (stored is not None and stored.status != "accepted"):
        raise typer.Exit(EXIT_VERDICT_FAIL)


def synth_motions(
    ctx: typer.Context,
    out: Annotated[
        Path, typer.Argument(metavar="OUT.csv", help="Motions CSV to write (plus OUT.truth.json).")
    ],
    shape: Annotated[
        str, typer.Option("--shape", help="poses (a trajectory in time) or motions (independent).")
    ] = "poses",
    rows: Annotated[int, typer.Option("--rows", min=2, help="Poses or motions to write.")] = 30,
    excitation: Annotated[str, typer.Option("--excitation", help="3d, planar or corridor.")] = "3d",
    amplitude_deg: Annotated[
        float, typer.Option("--amplitude-deg", min=0.0, help="Rotation excitation.")
    ] = 45.0,
    noise_rotation_deg: Annotated[
        float, typer.Option("--noise-rotation-deg", min=0.0, help="Per pose/motion.")
    ] = 0.05,
    noise_translation_mm: Annotated[
        float, typer.Option("--noise-translation-mm", min=0.0, help="Per pose/motion.")
    ] = 2.0,
    time_offset_ms: Annotated[
        float, typer.Option("--time-offset-ms", help="b's clock late by this (poses only).")
    ] = 0.0,
    rate_hz: Annotated[float, typer.Option("--rate-hz", min=0.01, help="Keyframe rate of a pose log.")] = 2.0,
    translation_m: Annotated[
        tuple[float, float, float], typer.Option("--translation-m", help="True X translation.")
    ] = (0.12, -0.05, 0.30),
    rotation_deg: Annotated[
        tuple[float, float, float], typer.Option("--rotation-deg", help="True X rotation vector, deg.")
    ] = (0.0, 0.0, 90.0),
    seed: Annotated[int, typer.Option("--seed", help="Random seed.")] = 0,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing files.")] = False,
    json_output: JsonFlag = False,
) -> None:
    """Write a motion log with a known X (truth beside it), chosen excitation, noise and time offset."""
    from calibctl.workflows.handeye import handeye as wf

    result = wf.run_synth_motions(
        wf.SynthRequest(
            out,
            shape,
            rows,
            excitation,
            amplitude_deg,
            noise_rotation_deg,
            noise_translation_mm / 1e3,
            time_offset_ms / 1e3,
            rate_hz,
            translation_m,
            rotation_deg,
            seed,
            force,
        )
    )
    if wants_json(ctx, json_output):
        emit_json(result)
        return
    stdout.print(
        f"{result['rows']} {shape} ({excitation}, {amplitude_deg:g} deg, noise {noise_rotation_deg:g} deg / "
        f"{noise_translation_mm:g} mm, time offset {time_offset_ms:g} ms, seed {seed}) with X translation "
        f"{tuple(translation_m)} m, rotation vector {tuple(rotation_deg)} deg"
    )
    for kind, path in result["files"].items():
        stdout.print(f"  {kind:<8} {escape(path)}")


def register(app: typer.Typer) -> None:
    """Add this module's commands to the root app."""
    app.command("handeye")(handeye)
    app.command("synth-motions")(synth_motions)
