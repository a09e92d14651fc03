"""calibctl diagnostics commands: triage, gauge, timeoffset, synth-residuals.

Each command parses, calls one workflow in calibctl.workflows.diagnostics.diagnostics, renders (rich tables
for people, the documented dict for --json) and exits 0 (pass), 1 (fault named, gauge alarm, time
offset refused) or 2 (via the error boundary: the input could not support an answer).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from calibctl.cli.context import wants_json
from calibctl.cli.render import emit_json, stdout
from calibctl.errors import EXIT_VERDICT_FAIL

JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
PlotDir = Annotated[Path | None, typer.Option("--plot", metavar="DIR", help="Write PNG plots into DIR.")]


def _finish(ctx: typer.Context, json_output: bool, result: dict[str, Any], render) -> None:
    if wants_json(ctx, json_output):
        emit_json(result)
    else:
        render(result)
    if result["verdict"] in ("fail", "refused"):
        raise typer.Exit(EXIT_VERDICT_FAIL)


def _fmt(key: str, v: float | None) -> str:
    if v is None:
        return "-"
    return {
        "focal": f"{v:+.5f}",
        "k1": f"{v:+.5f}",
        "lever_arm": f"{v * 1e3:+.2f} mm",
        "time_offset": f"{v * 1e3:+.3f} ms",
        "line_delay": f"{v * 1e6:+.3f} us/row",
        "rotation_or_principal_point": f"{v:+.4f} deg",
    }[key]


def _channel_row(c: dict) -> list[str]:
    ci = c["value_ci95"]
    if c["value"] is not None:
        value = _fmt(c["key"], c["value"])
        if c["key"] == "rotation_or_principal_point":
            value += f" (or {c['principal_point_px']:+.2f} px principal point)"
        interval = f"[{_fmt(c['key'], ci[0])}, {_fmt(c['key'], ci[1])}]" if ci else "-"
    else:
        value = f"{c['coef']:+.4g} {c['coef_unit']}" if c["coef"] is not None else "-"
        interval = "-"
    t = "-" if c["t"] is None else ("inf" if c["coef"] and c["se"] == 0 else f"{c['t']:+.1f}")
    effect = "-" if c["effect_px"] is None else f"{c['effect_px']:.2f}"
    status = c["status"].upper() if c["status"] == "fault" else c["status"]
    return [
        c["key"].replace("_", " "),
        value,
        interval,
        t,
        effect,
        status + (f" - {c['note']}" if c["note"] else ""),
    ]


def _render_triage(r: dict) -> None:
    stdout.print(f"Triage of {escape(r['input'])}  (focal {r['focal_px']:g} px, {r['focal_px_source']})")
    for cam in r["cameras"]:
        stdout.print(
            f"\n[bold]Camera {escape(cam['camera'])}[/bold]: {cam['n_rows']} rows, {cam['n_keyframes']} "
            f"{'keyframes' if cam['aggregation'] == 'keyframe means' else 'rows as units'} "
            f"({cam['aggregation']}), RMS {cam['rms_px']:.3f} px, joint fit dof {cam['dof']}, "
            f"names a fault at |t| >= {cam['t_critical']:.2f}"
        )
        table = Table(
            "channel",
            "value",
            "95% interval",
            "t",
            "effect px",
            "status",
            title="joint fit: 1, r, r^3, 1/Z, u, u*row",
        )
        for c in cam["channels"]:
            table.add_row(*_channel_row(c))
        stdout.print(table)
        marg = Table(
            "covariate",
            "slope",
            "95% interval",
            "t",
            title="per-covariate fits (with intercept; may be confounded)",
        )
        for m in cam["marginal"]:
            marg.add_row(
                m["covariate"] + (" (residual/u)" if m["covariate"] == "row" else ""),
                f"{m['slope']:+.4g} {m['slope_unit']}",
                f"[{m['ci95'][0]:+.4g}, {m['ci95'][1]:+.4g}]",
                f"{m['t']:+.1f}",
            )
        stdout.print(marg)
        for c in cam["collinear"]:
            stdout.print(f"collinear: {c['a']} and {c['b']} correlate at {c['corr']:+.4f}; not attributed")
        if cam["radial_order"]:
            ro = cam["radial_order"]
            stdout.print(
                f"radial order: r^3 {ro['b3_px_at_rmax']:+.3f} px at r_max (t {ro['t3']:+.1f}), r^5 "
                f"{ro['b5_px_at_rmax']:+.3f} px (t {ro['t5']:+.1f}), corr {ro['corr']:.4f}: {ro['reading']}"
            )
        if cam["thermal"]:
            th = cam["thermal"]
            text = (
                th.get("note")
                or f"RMS slope {th['slope_px_per_k']:+.4f} px/K (t {th['t']:+.1f}), threshold "
                f"{th['threshold_px_per_k']} px/K"
            )
            stdout.print(f"thermal: {th['status']}: {text}")
        stdout.print(f"[bold]Verdict {escape(cam['camera'])}:[/bold] {escape(cam['verdict'])}")
    rms = r["camera_rms"]
    if rms["max_over_min"] is not None:
        per = ", ".join(f"{escape(k)} {v:.3f} px" for k, v in rms["per_camera"].items())
        stdout.print(
            f"\nPer-camera RMS: {per}; max/min {rms['max_over_min']:.2f} -> {rms['level'].upper()} "
            f"(warn > {rms['warn_above']}, alarm > {rms['alarm_above']})"
        )
    _plots_and_result(r)


def _plots_and_result(r: dict) -> None:
    for p in r.get("plots", []):
        stdout.print(f"plot: {escape(p)}")
    stdout.print(f"Result: {r['verdict'].upper()}")


def triage(
    ctx: typer.Context,
    residuals: Annotated[
        Path,
        typer.Argument(
            metavar="RESIDUALS.csv",
            help="residual_px, radius_px, image_speed_px_s, "
            "inv_range_per_m, row [, camera, keyframe, temperature_c]",
        ),
    ],
    focal_px: Annotated[
        float | None,
        typer.Option("--focal-px", min=1.0, help="Focal length in px for unit conversion (default 800)."),
    ] = None,
    camera: Annotated[str | None, typer.Option("--camera", help="Triage only this camera.")] = None,
    t_min: Annotated[float, typer.Option("--t-min", min=1.0, help="Smallest |t| that names a fault.")] = 4.0,
    min_effect_px: Annotated[
        float, typer.Option("--min-effect-px", min=0.0, help="Smallest effect (px) that names a fault.")
    ] = 0.5,
    plot: PlotDir = None,
    json_output: JsonFlag = False,
) -> None:
    """Name the calibration fault behind a residual buffer (exit 1 when one is named)."""
    from calibctl.workflows.diagnostics import diagnostics as wf

    result = wf.run_triage(
        residuals, focal_px=focal_px, camera=camera, t_min=t_min, min_effect_px=min_effect_px, plot_dir=plot
    )
    _finish(ctx, json_output, result, _render_triage)


def _render_gauge(r: dict) -> None:
    stdout.print(
        f"Metric gauge of {escape(r['input'])}: distances {r['distances']}, {r['window_s']:g} s windows, "
        f"{r['stationary_samples']} stationary samples skipped"
    )
    table = Table("window [s]", "moving samples", "median wheel/VIO", "spread", "level")
    shown = r["windows"][:30]
    for w in shown:
        med = "-" if w["median_ratio"] is None else f"{w['median_ratio']:.4f}"
        spread = "-" if w["spread"] is None else f"{w['spread']:.4f}"
        table.add_row(
            f"{w['start_s']:.0f}-{w['end_s']:.0f}", str(w["n_samples"]), med, spread, w["level"].upper()
        )
    stdout.print(table)
    if len(r["windows"]) > len(shown):
        stdout.print(f"... {len(r['windows']) - len(shown)} more windows (see --json)")
    first = (
        ""
        if r["first_alarm_s"] is None
        else f", first alarm in the window starting at {r['first_alarm_s']:.0f} s"
    )
    stdout.print(
        f"[bold]{r['level'].upper()}[/bold]{first}: median {r['median_ratio']:.4f} "
        f"(warn outside {r['warn_band'][0]}-{r['warn_band'][1]}, alarm outside "
        f"{r['alarm_band'][0]}-{r['alarm_band'][1]})"
    )
    stdout.print(escape(r["diagnosis"]))
    _plots_and_result(r)


def gauge(
    ctx: typer.Context,
    odometry: Annotated[
        Path, typer.Argument(metavar="ODOMETRY.csv", help="t_s, wheel_distance_m, vio_distance_m")
    ],
    window_s: Annotated[float, typer.Option("--window-s", min=1.0, help="Window length in seconds.")] = 60.0,
    distances: Annotated[str, typer.Option("--distances", help="auto, cumulative or per-sample.")] = "auto",
    plot: PlotDir = None,
    json_output: JsonFlag = False,
) -> None:
    """Metric-gauge watchdog: 60 s medians of wheel/VIO distance (exit 1 on alarm)."""
    from calibctl.workflows.diagnostics import diagnostics as wf

    _finish(
        ctx,
        json_output,
        wf.run_gauge(odometry, window_s=window_s, distances=distances, plot_dir=plot),
        _render_gauge,
    )


def _render_timeoffset(r: dict) -> None:
    stdout.print(
        f"Time offset: {escape(r['gyro'])} vs {escape(r['camera'])}, resampled to {r['rate_hz']:g} Hz over "
        f"{r['overlap_s'][0]:.3f}..{r['overlap_s'][1]:.3f} s ({r['n_samples']} samples)"
    )
    if r["td_s"] is not None:
        ci = r["ci95_s"]
        stdout.print(
            f"[bold]td = {r['td_ms']:+.3f} ms[/bold] +/- {r['sigma_s'] * 1e3:.3f} ms (1 sigma, jackknife "
            "over "
            f"{r['jackknife_blocks']} blocks), 95% interval [{ci[0] * 1e3:+.3f}, {ci[1] * 1e3:+.3f}] ms"
        )
        stdout.print(
            f"peak NCC {r['peak_ncc']:.4f} at integer lag {r['integer_lag']}, parabolic refinement "
            f"{r['subsample']:+.3f} samples; gyro rate variation {r['rate_std_rad_s']:.3f} rad/s"
        )
    stdout.print(f"sign: {r['sign_convention']}")
    d = r["drift"]
    if d:
        if d["drift_ppm"] is not None:
            stdout.print(
                f"drift over {len(d['windows'])} windows of {d['window_s']:g} s: {d['drift_ppm']:+.2f} ppm "
                f"[{d['ci95_ppm'][0]:+.2f}, {d['ci95_ppm'][1]:+.2f}] (dof {d['dof']}): {d['reading']}"
            )
        else:
            stdout.print(f"drift: {d['reading']}")
    if r["reason"]:
        stdout.print(f"[bold]REFUSED:[/bold] {escape(r['reason'])}")
    _plots_and_result(r)


def timeoffset(
    ctx: typer.Context,
    gyro: Annotated[Path, typer.Argument(metavar="GYRO.csv", help="t_s, rate_rad_s from the IMU")],
    camera: Annotated[
        Path, typer.Argument(metavar="CAMERA.csv", help="t_s, rate_rad_s derived from the images")
    ],
    rate_hz: Annotated[
        float | None, typer.Option("--rate-hz", min=1.0, help="Common rate (default: the faster log's).")
    ] = None,
    max_lag_s: Annotated[
        float, typer.Option("--max-lag-s", min=0.001, help="Search td within +/- this.")
    ] = 0.2,
    max_sigma_ms: Annotated[
        float, typer.Option("--max-sigma-ms", min=0.001, help="Refuse above this standard error.")
    ] = 2.0,
    window: Annotated[
        float | None,
        typer.Option("--window", metavar="S", min=1.0, help="Also fit drift (ppm) over S-second windows."),
    ] = None,
    plot: PlotDir = None,
    json_output: JsonFlag = False,
) -> None:
    """Camera-IMU time offset by cross-correlating angular rate (exit 1 when the motion cannot pin it)."""
    from calibctl.workflows.diagnostics import diagnostics as wf

    result = wf.run_timeoffset(
        gyro,
        camera,
        rate_hz=rate_hz,
        max_lag_s=max_lag_s,
        max_sigma_ms=max_sigma_ms,
        window_s=window,
        plot_dir=plot,
    )
    _finish(ctx, json_output, result, _render_timeoffset)


def _render_synth(r: dict) -> None:
    stdout.print(
        f"Injected {r['fault']} = {r['magnitude']:g} {r['magnitude_unit']} into {r['faulty_camera']} "
        f"(noise {r['noise_px']:g} px, seed {r['seed']}): {r['rows']} rows, {r['keyframes']} keyframes x "
        f"{r['cameras']} camera(s)"
    )
    for kind, path in r["files"].items():
        stdout.print(f"  {kind:<9} {escape(path)}")


def synth_residuals(
    ctx: typer.Context,
    out: Annotated[
        Path,
        typer.Argument(
            metavar="OUT.csv", help="Residual buffer to write (plus OUT_odometry/_gyro/_camera.csv)."
        ),
    ],
    fault: Annotated[
        str,
        typer.Option(
            "--fault", help="focal|k1|principal-point|rotation|translation|time-offset|rolling-shutter|gauge"
        ),
    ],
    magnitude: Annotated[
        float | None, typer.Option("--magnitude", help="Fault size in its own unit (default: the seed's).")
    ] = None,
    noise_px: Annotated[float, typer.Option("--noise-px", min=0.0, help="Per-feature noise (px).")] = 0.3,
    seed: Annotated[int, typer.Option("--seed", help="Random seed.")] = 0,
    keyframes: Annotated[int, typer.Option("--keyframes", min=1, help="Keyframes per camera.")] = 500,
    features: Annotated[int, typer.Option("--features", min=1, help="Features per keyframe.")] = 80,
    cameras: Annotated[int, typer.Option("--cameras", min=1, help="Cameras; the fault goes into cam0.")] = 1,
    slip: Annotated[
        float, typer.Option("--slip", min=0.0, help="Zero-mean wheel slip per sample (odometry log).")
    ] = 0.01,
    drift_ppm: Annotated[
        float, typer.Option("--drift-ppm", help="Camera clock drift in the rate logs.")
    ] = 0.0,
    rate_log_s: Annotated[
        float, typer.Option("--rate-log-s", min=1.0, help="Length of the gyro/camera logs (s).")
    ] = 20.0,
    odometry_s: Annotated[
        float, typer.Option("--odometry-s", min=1.0, help="Length of the odometry log (s).")
    ] = 600.0,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing files.")] = False,
    json_output: JsonFlag = False,
) -> None:
    """Write a residual buffer with one injected fault, plus matching odometry and rate logs."""
    from calibctl.workflows.diagnostics import diagnostics as wf

    result = wf.run_synth(
        out,
        fault,
        magnitude=magnitude,
        noise_px=noise_px,
        seed=seed,
        keyframes=keyframes,
        features=features,
        cameras=cameras,
        slip=slip,
        odometry_s=odometry_s,
        rate_log_s=rate_log_s,
        drift_ppm=drift_ppm,
        force=force,
    )
    _finish(ctx, json_output, result, _render_synth)


def register(app: typer.Typer) -> None:
    """Add this module's commands to the root app."""
    app.command("triage")(triage)
    app.command("gauge")(gauge)
    app.command("timeoffset")(timeoffset)
    app.command("synth-residuals")(synth_residuals)
