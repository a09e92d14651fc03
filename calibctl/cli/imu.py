"""calibctl imu solve / synth: camera-IMU extrinsics and time offset from a recording (docs/imu.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.render import emit_json, say

imu_app = typer.Typer(
    name="imu",
    help="Camera-IMU calibration: T_imu_cam and the time offset td from a recording, gated, with one-sigma.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]

TD_GATES = ("td_rotation_correlation", "td_sigma")  # failed: holding td is the other way out


def render_result(doc: dict[str, Any]) -> None:
    """Human report of ``imu_solve.result_json``'s document."""
    say(
        f"imu solve: {doc['recording']}: {doc['frames']} frames, {doc['imu_samples']} IMU samples at "
        f"{doc['imu_rate_hz']} Hz; intrinsics held from {doc['camera']}; noise {doc['noise']}"
    )
    for note in doc["notes"]:
        say(f"  note: {note}")
    for g in doc["gates"]:
        say(f"  gate {g['gate']:<30}{'pass' if g['passed'] else 'FAIL'}  {g['message']}")
        if not g["passed"] and g["hint"]:
            say(f"       hint: {g['hint']}")
        if not g["passed"] and g["gate"] in TD_GATES and not doc["held"]:  # the core's hint names no flag
            say("       to hold td: imu solve ... --hold-td-ms MS (0 on a hardware-triggered rig)")
    if doc["held_reason"]:
        say(f"  held: {doc['held_reason']}")
    e = doc["estimate"]
    if e is not None:
        say(f"{e['name']} ({e['convention']}):")
        say(
            "  translation "
            + ", ".join(
                f"{a} {v * 1e3:+.1f} +/- {s:.2f} mm"
                for a, v, s in zip("xyz", e["translation_m"], e["sigma_translation_mm"], strict=True)
            )
        )
        say(
            "  rotation sigma about IMU x, y, z "
            + ", ".join(f"{v:.4f}" for v in e["sigma_rotation_deg"])
            + " deg"
        )
        say(
            f"td {e['td_ms']:+.3f} ms ({e['td_convention']})"
            + (" HELD" if e["td_held"] else f" +/- {e['sigma_td_ms']:.3f} ms")
            + ("" if e["td_crlb_ms"] is None else f"; CRLB {e['td_crlb_ms']:.3f} ms")
        )
        if "imu_intrinsics" in e:
            m = e["imu_intrinsics"]
            say(f"IMU model {e['imu_model']} (deviation from identity +/- one-sigma):")
            groups = (("mg", "M_gyro"), ("cg", "C_gyro_i rad"), ("ma", "M_accel"), ("ag", "A_gyro"))
            for prefix, what in groups:
                say(
                    f"  {what}: "
                    + ", ".join(
                        f"{k[3:]} {v:+.5f} +/- {m['sigmas'][k]:.5f}"
                        for k, v in m["states"].items()
                        if k.startswith(prefix)
                    )
                )
        if e["line_delay_us"] is not None:
            say(f"rolling-shutter line delay {e['line_delay_us']:.3f} +/- {e['sigma_line_delay_us']} us/row")
        if doc["row_test"] is not None:
            say(f"  row test: {doc['row_test']['message']}")
        m = doc["metrics"]
        held = m["held_out_corner_rms_px"]
        say(
            f"  reprojection RMS {m['corner_rms_px']:.3f} px ({m['corners_left_out']} corners left out), "
            f"gyro RMS {m['gyro_rms_rad_s']:.5f} rad/s, accel RMS {m['accel_rms_m_s2']:.4f} m/s^2"
            + (f"; held-out reprojection {max(held):.3f} px worst of {m['folds']} folds" if held else "")
        )
    if doc["status"] == "accepted":
        say("Result: ACCEPTED")
    else:
        failed = [
            g["message"]
            for g in doc["gates"]
            if not g["passed"] and g["gate"] != "td_rotation_correlation_free"
        ]
        say("Result: REJECTED" + ("" if e else " (no estimate reported)") + ": " + "; ".join(failed))


@imu_app.command("solve")
def solve(
    ctx: typer.Context,
    recording: Annotated[
        Path,
        typer.Argument(
            metavar="RECORDING",
            help="Folder with imu0/data.csv (or imu0.csv: ns, rad/s, m/s^2) and CAMERA/<ns>.csv corner "
            "files (stamp, kp_x, kp_y, p_x, p_y, p_z) or ASL images (CAMERA/data.csv, CAMERA/data/, with "
            "--board); or a ROS 1 .bag / ROS 2 bag folder (--image-topic, --imu-topic, --board).",
        ),
    ],
    serial: Annotated[
        list[str],
        typer.Option(
            "--serial",
            help="The camera: its active stored calibration's intrinsics are held. Repeat it with --camera "
            "to solve several cameras against one IMU in one solve (pairs in order).",
        ),
    ],
    camera: Annotated[
        list[str] | None,
        typer.Option("--camera", help="The camera's folder in RECORDING (default cam0); one per --serial."),
    ] = None,
    noise: Annotated[
        Path | None,
        typer.Option("--noise", help="Kalibr imu.yaml (noise densities, random walks); default EuRoC's."),
    ] = None,
    hold_td_ms: Annotated[
        float | None,
        typer.Option(
            "--hold-td-ms",
            help="When the motion cannot separate td from the extrinsic rotation, hold td here "
            "(a hardware-triggered rig: 0) instead of refusing.",
        ),
    ] = None,
    line_delay: Annotated[
        bool, typer.Option("--line-delay", help="Estimate a rolling-shutter line delay too.")
    ] = False,
    knot_spacing_ms: Annotated[
        float, typer.Option("--knot-spacing-ms", min=5.0, max=500.0, help="Trajectory spline knot spacing.")
    ] = 50.0,
    folds: Annotated[int, typer.Option("--folds", min=0, max=10, help="k of the k-fold held-out check.")] = 3,
    rig: Annotated[
        str | None,
        typer.Option(
            "--rig",
            help="Store the result as the rig's next version: edge IMU_FRAME -> SERIAL of its tree "
            "(rejected results never active).",
        ),
    ] = None,
    imu_frame: Annotated[
        str, typer.Option("--imu-frame", help="The IMU's frame, declared in the rig.")
    ] = "imu",
    board: Annotated[
        str | None,
        typer.Option(
            "--board",
            help="Registered board NAME[@REV]: detects the corners in CAMERA/data/ images (ASL: "
            "CAMERA/data.csv lists them), and checks corner files' board points.",
        ),
    ] = None,
    image_topic: Annotated[
        str | None,
        typer.Option("--image-topic", help="RECORDING a ROS 1/2 bag: its sensor_msgs/Image topic."),
    ] = None,
    imu_topic: Annotated[
        str | None, typer.Option("--imu-topic", help="RECORDING a ROS 1/2 bag: its sensor_msgs/Imu topic.")
    ] = None,
    imu_model: Annotated[
        str,
        typer.Option(
            "--imu-model",
            help="Kalibr's IMU model: calibrated (biases only), or scale-misalignment (gyro and "
            "accelerometer scale and axis misalignment, gyro-to-accelerometer rotation, gyro "
            "g-sensitivity, weak priors; refused when the recording cannot pin them).",
        ),
    ] = "calibrated",
    bias_walk: Annotated[
        bool,
        typer.Option(
            "--bias-walk",
            help="Let the gyro and accelerometer biases wander as random walks (Kalibr's bias splines, "
            "weighted by the noise file's random-walk densities) instead of constant.",
        ),
    ] = False,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Write the result JSON here.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite --out.")] = False,
    json_output: JsonFlag = False,
) -> None:
    """Solve T_imu_cam and td; exit 1 when a gate rejects the recording or the estimate."""
    from calibctl.cli.stored_edge import finish_solve, stored_line, stored_summary
    from calibctl.errors import UsageError
    from calibctl.workflows.imu import imu_solve as wf

    if imu_model not in wf.IMU_MODELS:
        raise UsageError(f"unknown --imu-model {imu_model!r}", f"use one of {', '.join(wf.IMU_MODELS)}")
    cameras = camera or ["cam0"]
    if len(cameras) != len(serial):
        raise UsageError(
            f"{len(cameras)} --camera for {len(serial)} --serial",
            "give one --camera FOLDER per --serial SERIAL, in the same order",
        )
    req = wf.ImuRequest(
        recording,
        serial[0],
        cameras[0],
        noise,
        imu_frame,
        rig,
        None if hold_td_ms is None else hold_td_ms / 1e3,
        line_delay,
        knot_spacing_ms / 1e3,
        folds,
        out,
        force,
        board,
        image_topic,
        imu_topic,
        tuple(zip(cameras[1:], serial[1:], strict=True)),
        imu_model,
        bias_walk,
    )
    outcome = wf.run_imu(state(ctx).settings(), req)
    doc = wf.result_json(outcome)
    as_json = wants_json(ctx, json_output)
    written = list(outcome.written)
    for o, more in zip(outcome.others, doc.get("more_cameras", []), strict=True):
        if o.stored is not None:
            more["stored"] = stored_summary(o.stored)
            written.append(f"{o.request.serial}: {stored_line(o.stored)}")
    accepted = all(
        o.accepted and (o.stored is None or o.stored.status == "accepted") for o in outcome.cameras
    )
    finish_solve(doc, as_json, render_joint, accepted, outcome.stored, written)


def render_joint(doc: dict[str, Any]) -> None:
    """Human report of a solve: the first camera, then each further camera of a joint solve."""
    if "more_cameras" in doc:
        say(f"camera {doc['camera_folder']} ({doc['serial']}):")
    render_result(doc)
    for more in doc.get("more_cameras", []):
        say(f"camera {more['camera_folder']} ({more['serial']}), solved jointly against the same IMU:")
        render_result(more)


@imu_app.command("synth")
def synth(
    ctx: typer.Context,
    out: Annotated[
        Path, typer.Argument(metavar="OUT_DIR", help="Folder for imu0/, cam0/, imu.yaml, truth.json.")
    ],
    seed: Annotated[int, typer.Option("--seed", help="Random seed.")] = 0,
    motion: Annotated[
        str,
        typer.Option("--motion", help="dance (rate reversals on every axis) or corridor (constant rate)."),
    ] = "dance",
    duration_s: Annotated[float, typer.Option("--duration-s", help="Recording length, seconds.")] = 6.0,
    td_ms: Annotated[float, typer.Option("--td-ms", help="Time offset rendered: t_imu = t_cam + td.")] = 12.0,
    line_delay_us: Annotated[
        float, typer.Option("--line-delay-us", help="Rolling-shutter line delay rendered, us per row.")
    ] = 0.0,
    serial: Annotated[
        str | None,
        typer.Option("--serial", help="Render through this camera's active stored calibration."),
    ] = None,
    images: Annotated[
        bool,
        typer.Option(
            "--images",
            help="Write the ASL image layout (cam0/data.csv + cam0/data/*.png, a 7x6 inner-corner "
            "chessboard of 50 mm squares) instead of corner files.",
        ),
    ] = False,
    pattern: Annotated[
        str,
        typer.Option(
            "--pattern",
            help="With --images: chessboard, or aprilgrid (Kalibr's target: 6x5 tags of 55 mm, spacing 0.3, "
            "tag36h11; truth.json's board holds its target.yaml fields).",
        ),
    ] = "chessboard",
    stereo: Annotated[
        bool,
        typer.Option(
            "--stereo",
            help="Also render a second camera of the rig (cam1/, 11 cm along cam0's x, same lens and clock).",
        ),
    ] = False,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing recording.")] = False,
    json_output: JsonFlag = False,
) -> None:
    """Render a camera + IMU recording with known T_imu_cam and td (truth.json beside it)."""
    from calibctl.workflows.imu.imu_synth import run_imu_synth

    result = run_imu_synth(
        state(ctx).settings(),
        out,
        seed,
        motion=motion,
        duration_s=duration_s,
        td_s=td_ms / 1e3,
        line_delay_s=line_delay_us / 1e6,
        serial=serial,
        images=images,
        pattern=pattern,
        stereo=stereo,
        force=force,
    )
    if wants_json(ctx, json_output):
        emit_json(result)
        return
    say(
        f"{result['frames']} frames, {result['imu_samples']} IMU samples ({motion}, seed {seed}) in {out}; "
        f"truth {result['truth']}"
    )


def register(app: typer.Typer) -> None:
    """Add the ``imu`` command group to the root app."""
    app.add_typer(imu_app, name="imu")
