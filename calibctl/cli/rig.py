"""calibctl rig solve-folders: stereo and multi-camera extrinsics from per-camera photo folders."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import (
    JobsOption,
    OperatorOption,
    OverrideGaugeOption,
    ReferenceDistanceOption,
    RigTimestampsOption,
    RigTimeToleranceOption,
    StationOption,
)
from calibctl.cli.render import emit_json, say
from calibctl.cli.rig_render import print_findings, render_run, render_unmatched
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.errors import EXIT_VERDICT_FAIL, UsageError, named_list

RigReferenceSourceOption = Annotated[
    str | None,
    typer.Option(
        "--reference-source",
        metavar="SERIAL=SRC",
        show_default=False,
        help="With --reference-distance: one camera's pictures of the board in the fixture; the gauge is "
        "judged through that camera's lens (its own photos' solve), as `capture --reference-distance` does.",
    ),
]

rig_app = typer.Typer(
    name="rig",
    help="Camera rigs: extrinsics of 2+ cameras as a tree from one root, with one-sigma per edge.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@rig_app.command("solve-folders")
def solve_folders(
    ctx: typer.Context,
    source: Annotated[
        list[str],
        typer.Option(
            "--source",
            help="SERIAL=SRC, one per camera, SRC a folder, a quoted "
            "glob ('left*.jpg'), a list file as for capture, or a video; the first is the "
            "root unless --root. Photos pair up by the last number in their "
            "names; videos (or --timestamps) by time.",
        ),
    ],
    cols: Annotated[int, typer.Option("--cols", help="Inner corners per row.")],
    rows: Annotated[int, typer.Option("--rows", help="Inner corners per column.")],
    square_mm: Annotated[
        float, typer.Option("--square-mm", help="Square edge, millimetres (measured, ideally).")
    ],
    kind: Annotated[str, typer.Option("--kind", help="chessboard or charuco.")] = "chessboard",
    marker_mm: Annotated[
        float | None, typer.Option("--marker-mm", help="ChArUco marker edge, mm.", show_default=False)
    ] = None,
    dictionary: Annotated[
        str | None,
        typer.Option("--dictionary", help="ChArUco dictionary, e.g. DICT_4X4_1000.", show_default=False),
    ] = None,
    inverted: Annotated[
        bool, typer.Option("--inverted", help="ChArUco printed white markers on black squares.")
    ] = False,
    legacy: Annotated[bool, typer.Option("--legacy", help="ChArUco in the layout of OpenCV < 4.6.")] = False,
    timestamps: Annotated[
        Path | None,
        typer.Option(
            "--timestamps",
            help="The recorder's per-frame times (CSV cam_id,frame_index,frame_time; cam_id = the SERIAL of "
            "--source): frames pair up by time. Without it videos pair by their own per-frame times.",
            show_default=False,
        ),
    ] = None,
    time_tolerance_ms: Annotated[
        float,
        typer.Option(
            "--time-tolerance-ms",
            help="Frames of different cameras at most this far apart form one rig frame.",
        ),
    ] = 5.0,
    frame_shift: Annotated[
        list[str] | None,
        typer.Option(
            "--frame-shift",
            help="SERIAL=N: that camera's video frame i was taken at the time listed for its frame i - N "
            "(a recorder whose video holds N frames its timestamps do not list first; rig-frame-shift "
            "names it).",
            show_default=False,
        ),
    ] = None,
    exposure_offset: Annotated[
        list[str] | None,
        typer.Option(
            "--exposure-offset",
            help="SERIAL=MS: that camera's frames were exposed MS ms after their listed times (a latency "
            "the timestamps miss; rig-exposure-offset names it): its corners are interpolated to the listed "
            "times between neighbouring frames.",
            show_default=False,
        ),
    ] = None,
    estimate_exposure_offset: Annotated[
        list[str] | None,
        typer.Option(
            "--estimate-exposure-offset",
            help="SERIAL: estimate that camera's exposure offset from the data (the rig's residual over "
            "the offset, its minimum and a frame-bootstrap sd) and apply it; exit 2 when the frames cannot "
            "show it.",
            show_default=False,
        ),
    ] = None,
    root: Annotated[
        str | None, typer.Option("--root", help="Root camera of the tree.", show_default=False)
    ] = None,
    model: Annotated[
        str, typer.Option("--model", help="Each camera's intrinsic model (core solve models).")
    ] = DEFAULT_MODEL,
    refine_intrinsics: Annotated[
        bool, typer.Option("--refine-intrinsics", help="Refine intrinsics jointly.")
    ] = False,
    min_shared_views: Annotated[
        int, typer.Option("--min-shared-views", help="Rig gate: frames per linking pair.")
    ] = 5,
    design: Annotated[
        list[str] | None,
        typer.Option(
            "--design-baseline-mm",
            help="A:B=75.0+-0.5: a pair's design "
            "baseline, mm (repeat per pair); a solved baseline outside it "
            "fails baseline-design.",
            show_default=False,
        ),
    ] = None,
    export_dir: Annotated[
        Path | None,
        typer.Option(
            "--export-dir",
            help="Write the robot exports here (only when the verdict passes).",
            show_default=False,
        ),
    ] = None,
    allow_rejected: Annotated[
        bool,
        typer.Option(
            "--allow-rejected",
            help="Write the exports of a failed verdict too (to inspect them; a robot must not load them).",
        ),
    ] = False,
    reference_distance: ReferenceDistanceOption = None,
    reference_source: RigReferenceSourceOption = None,
    jobs: JobsOption = None,
    json_output: Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")] = False,
) -> None:
    """Solve a rig from per-camera folders (no store): exit 0 pass, 1 fail (rig gate, or the verdict a
    stored rig solve would give), 2 could not solve.

    Each camera is first calibrated on its own photos; then the extrinsics (cv2.stereoCalibrateExtended
    for two cameras, calibctl's joint LM for more), their one-sigma, k-fold held-out epipolar error and
    rectified rows per pair, and loop closure for three or more cameras. The verdict: the rig lint rules
    that need no store (baseline-design, epipolar, loop-closure; the station's limits), each camera judged
    as the stored path judges it (its capture gates, then its calibration's lint: member:<rule>; not the
    square size's provenance, which only a registered board carries), rig-rigid (frames that no
    rigid, synchronised rig could have taken), rig-frame-shift (a camera whose frames fit the others' a
    whole frame off its times) and rig-exposure-offset (a pair exposed further apart than its times say).
    With --reference-distance, metric-gauge: one camera's fixture pictures judged through its lens as the
    run leaves it.
    """
    from calibctl.workflows.rig import rig_folders

    sources = rig_folders.parse_sources(source)
    if root is not None:
        if root not in sources:
            raise UsageError(f"--root {root} is not one of the cameras ({', '.join(sources)})")
        sources = {root: sources[root], **{k: v for k, v in sources.items() if k != root}}
    spec = rig_folders.typed_spec(kind, cols, rows, square_mm, marker_mm, dictionary, inverted, legacy)
    from calibctl.workflows.rig.rig_lint import parse_design

    designs = [parse_design(d) for d in design or []]
    settings = state(ctx).settings(jobs=jobs)
    run = rig_folders.solve_rig_folders(
        sources,
        spec,
        model,
        None,
        refine_intrinsics,
        min_shared_views,
        workers=settings.jobs,
        settings=settings,
        designs=designs,
        gauge=rig_gauge(reference_distance, reference_source),
        timestamps=timestamps,
        time_tolerance_ms=time_tolerance_ms,
        frame_shifts=rig_folders.parse_frame_shifts(frame_shift or []),
        exposure_offsets_ms=rig_folders.parse_exposure_offsets(exposure_offset or []),
        estimate_offsets=estimate_exposure_offset or [],
    )
    doc = rig_folders.run_json(run)
    exports: list[str] = []
    withheld = export_dir is not None and run.solution is not None and not run.passed and not allow_rejected
    if export_dir is not None and run.solution is not None and not withheld:
        from calibctl.workflows.exports.rig_exports import solution_sha256, write_exports

        exports = [
            str(p)
            for p in write_exports(run.solution, export_dir, status="accepted" if run.passed else "rejected")
        ]
        doc["exports"] = exports
        doc["solution_sha256"] = solution_sha256(run.solution)
    if wants_json(ctx, json_output):
        emit_json(doc)
    else:
        render_run(doc)
        for path in exports:
            say(f"  wrote {path}")
        if exports:
            say(f"  exports: not stored (no rig version), solution sha256 {doc['solution_sha256']}")
        if withheld:
            say(
                f"  exports not written to {export_dir}: the verdict failed (--allow-rejected writes them to "
                "inspect; a robot must not load them)"
            )
    if not run.passed:
        raise typer.Exit(EXIT_VERDICT_FAIL)


JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]


@rig_app.command("add")
def add(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(metavar="RIG", help="Rig name.")],
    camera: Annotated[list[str], typer.Option("--camera", help="Member camera serial (repeat; 2 or more).")],
    root: Annotated[
        str | None, typer.Option("--root", help="Root camera (default: the first).", show_default=False)
    ] = None,
    design: Annotated[
        list[str] | None,
        typer.Option(
            "--design-baseline-mm",
            help="A:B=75.0+-0.5: design baseline and tolerance, mm (repeat per pair).",
            show_default=False,
        ),
    ] = None,
    frame: Annotated[
        list[str] | None,
        typer.Option(
            "--frame",
            help="Non-camera frame (flange, imu, lidar) a "
            "hand-eye, LiDAR or IMU edge may join to the tree (repeat).",
            show_default=False,
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Register a rig: its member cameras (each calibrated already), the root of its tree, design
    baselines."""
    from calibctl.workflows.rig import rigs

    rig = rigs.add_rig(state(ctx).settings(), name, camera, root, design or [], frame or [])
    if wants_json(ctx, json_output):
        emit_json(rig)
        return
    say(
        f"rig {rig.name}: cameras {', '.join(rig.cameras)}, root {rig.root}"
        + "".join(
            f"; design {d.a}-{d.b} {d.baseline_mm:.3f} +/- {d.tolerance_mm:.3f} mm"
            for d in rig.design_baselines
        )
        + (f"; frames {', '.join(rig.frames)}" if rig.frames else "")
    )


@rig_app.command("capture")
def capture(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(metavar="RIG", help="Registered rig.")],
    source: Annotated[
        list[str],
        typer.Option(
            "--source",
            help="SERIAL=SRC per member, SRC a folder, a quoted glob "
            "('left*.jpg') or a list file; images pair up by the last number in "
            "their names (with --timestamps: by time).",
        ),
    ],
    board: Annotated[str, typer.Option("--board", help="Registered board (NAME or NAME@REV).")],
    timestamps: RigTimestampsOption = None,
    time_tolerance_ms: RigTimeToleranceOption = None,
    min_shared_views: Annotated[
        int, typer.Option("--min-shared-views", help="Rig gate: frames per linking pair.")
    ] = 5,
    reference_distance: ReferenceDistanceOption = None,
    reference_source: RigReferenceSourceOption = None,
    override_gauge: OverrideGaugeOption = None,
    station: StationOption = None,
    operator: OperatorOption = None,
    jobs: JobsOption = None,
    json_output: JsonFlag = False,
) -> None:
    """Capture every member (its own outcomes and gates) and pair the images; exit 1 when the rig gate fails
    or the board revision has a failed metric gauge (this capture's, or one stored) not overridden."""
    from calibctl.workflows.rig import rig_folders, rigs

    sources = {k: str(v) for k, v in rig_folders.parse_sources(source).items()}
    result = rigs.capture_rig(
        state(ctx).settings(station=station, operator=operator, jobs=jobs),
        name,
        sources,
        board,
        min_shared_views,
        gauge=rig_gauge(reference_distance, reference_source),
        override_gauge=override_gauge,
        timestamps=timestamps,
        time_tolerance_ms=time_tolerance_ms,
    )
    s = result.session
    if wants_json(ctx, json_output):
        emit_json(
            {
                "rig_session": s.model_dump(mode="json"),
                "camera_sessions": {c: r.session.model_dump(mode="json") for c, r in result.cameras.items()},
            }
        )
    else:
        say(
            f"rig session {s.rig_session_id} of {s.rig}: {len(s.frames)} synchronised frames, "
            f"{len(s.unmatched)} unmatched image(s); {s.status}"
        )
        for c, r in result.cameras.items():
            gates = ", ".join(f"{g.gate} {'pass' if g.passed else 'FAIL'}" for g in r.session.gates)
            say(f"  {c}: session {r.session.session_id}, {len(r.session.views)} views ({gates})")
        render_unmatched([(u.camera, Path(u.name).name, u.reason) for u in s.unmatched])
        say("  shared views: " + ", ".join(f"{p} {n}" for p, n in s.shared_views.items()))
        for g in s.gates:
            say(
                f"  gate {g.gate} {'pass' if g.passed else 'FAIL'}  {g.message}"
                + (f" -> {g.hint}" if g.hint else "")
            )
    if not result.passed:
        raise typer.Exit(EXIT_VERDICT_FAIL)


def rig_gauge(reference_distance: str | None, reference_source: str | None) -> Any:
    """``--reference-distance D+-S --reference-source SERIAL=SRC`` -> ``rigs.RigGauge`` (None without)."""
    from calibctl.workflows.camera.distance_gauge import parse_reference_distance
    from calibctl.workflows.rig.rig_folders import RigGauge

    if (reference_distance is None) != (reference_source is None):
        raise UsageError(
            "--reference-distance and --reference-source go together",
            "give the surveyed distance D+-S and one member's fixture pictures, SERIAL=FOLDER",
        )
    if reference_distance is None or reference_source is None:
        return None
    camera, sep, fixture = reference_source.partition("=")
    if not sep or not camera or not fixture:
        raise UsageError(
            f"--reference-source '{reference_source}' is not SERIAL=SRC",
            "name the member whose fixture pictures these are, e.g. --reference-source CAM-L=fixture/",
        )
    return RigGauge(camera, parse_reference_distance(reference_distance), fixture)


def print_rig_calibration(cal: Any, active: bool) -> None:
    say(
        f"rig {cal.rig}@{cal.version} ({'active' if active else 'not active'})  {cal.status}  root "
        f"{cal.root}  "
        f"{cal.solver}"
    )
    for m in cal.members:
        say(
            f"  member {m.serial}@{m.version} {m.image_size[0]}x{m.image_size[1]} fx "
            f"{m.camera_matrix[0][0]:.2f}"
            f"{' (refined)' if m.refined else ''}: RMS fit {cal.fit_rms_px[m.serial]:.3f} px / held-out "
            f"{cal.held_out_rms_px[m.serial]:.3f} px"
        )
    for e in cal.edges:
        say(
            f"  T_{e.parent}_{e.child}: |t| = {e.translation_mm:.3f} +/- {e.sigma_translation_mm:.3f} mm, "
            f"rotation {e.rotation_deg:.4f} +/- {e.sigma_rotation_deg:.4f} deg ({e.source})"
        )
    for h in cal.handeye:
        failed = [g.gate for g in h.gates if not g.passed]
        say(
            f"  hand-eye {h.parent_frame} -> {h.child_frame}: {h.status}"
            + (f" (gates failed: {', '.join(failed)}; no edge)" if failed else "")
            + f", {len(h.motions)} motions from {h.provenance.input_file}"
            + (f", camera {h.provenance.camera}" if h.provenance.camera else "")
        )
    for ir in cal.imu:
        failed = [g.gate for g in ir.gates if not g.passed]
        est = ir.estimate
        say(
            f"  imu {ir.parent_frame} -> {ir.child_frame}: {ir.status}"
            + (f" (gates failed: {', '.join(failed)}; no edge)" if failed else "")
            + (
                ""
                if est is None
                else f", td {est.td_s * 1e3:+.3f} ms"
                + (" (held)" if est.td_held else f" +/- {est.sigma_td_ms:.3f} ms")
                + " (t_imu = t_cam + td)"
            )
            + f", camera {ir.camera}, recording {ir.recording}"
        )
    for lr in cal.lidar:
        failed = [g.gate for g in lr.gates if not g.passed]
        m = lr.metrics
        say(
            f"  lidar {lr.parent_frame} -> {lr.child_frame}: {lr.status}"
            + (f" (gates failed: {', '.join(failed)}; no edge)" if failed else "")
            + f", {sum(r.outcome == 'accepted' for r in lr.scans_outcomes)} of {len(lr.scans_outcomes)} "
            "scans accepted"
            + (
                f", point-to-plane RMS {m.plane_rms_mm:.1f} mm (held-out {m.held_out_plane_rms_mm:.1f} mm)"
                if m is not None and m.held_out_plane_rms_mm is not None
                else ""
            )
            + f", camera {lr.camera}"
        )
    for p in cal.pairs:
        epi = f"; held-out epipolar RMS {p.epipolar_rms_px:.3f} px" if p.epipolar_rms_px is not None else ""
        say(f"  pair {p.a}-{p.b}: baseline {p.baseline_mm:.3f} +/- {p.sigma_baseline_mm:.3f} mm{epi}")
    for lc in cal.loops:
        say(
            f"  loop {'-'.join(lc.cycle)}: {lc.rotation_deg:.4f} deg, {lc.translation_mm:.3f} mm, "
            f"Mahalanobis {lc.mahalanobis:.2f}"
        )
    print_findings(cal.lint)


@rig_app.command("solve")
def solve(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(metavar="RIG", help="Registered rig.")],
    session: Annotated[
        str | None, typer.Argument(metavar="[RIG_SESSION]", help="Rig session (default: latest accepted).")
    ] = None,
    refine_intrinsics: Annotated[
        bool, typer.Option("--refine-intrinsics", help="Refine members' intrinsics.")
    ] = False,
    activate: Annotated[
        bool, typer.Option("--activate/--no-activate", help="Make an accepted result active.")
    ] = True,
    json_output: JsonFlag = False,
) -> None:
    """Solve a rig capture into the rig's next version; exit 0 accepted, 1 rejected by lint, 2 could not
    solve."""
    from calibctl.workflows.rig import rigs

    out = rigs.solve_rig_stored(state(ctx).settings(), name, session, refine_intrinsics, activate=activate)
    if wants_json(ctx, json_output):
        emit_json(out.calibration)
    else:
        print_rig_calibration(out.calibration, out.active)
    if out.calibration.status != "accepted":
        raise typer.Exit(EXIT_VERDICT_FAIL)


@rig_app.command("lint")
def lint(
    ctx: typer.Context,
    ref: Annotated[str, typer.Argument(metavar="RIG[@N]", help="Rig (its active version) or RIG@N.")],
    json_output: JsonFlag = False,
) -> None:
    """Rig lint against the store as it is now (stale members, design baseline, epipolar, loops, members)."""
    from calibctl.workflows.rig import rig_lint

    result = rig_lint.lint_rig(state(ctx).settings(), ref)
    if wants_json(ctx, json_output):
        emit_json(result.as_json())
    else:
        say(f"{result.source}: {'fail' if result.failed else 'pass'}")
        print_findings(result.findings)
    if result.failed:
        raise typer.Exit(EXIT_VERDICT_FAIL)


@rig_app.command("history")
def history(
    ctx: typer.Context, name: Annotated[str, typer.Argument(metavar="RIG")], json_output: JsonFlag = False
) -> None:
    """Every version of a rig, which one is active, and the activation log."""
    from calibctl.workflows.rig import rig_lint

    cals, active, events = rig_lint.history(state(ctx).settings(), name)
    if wants_json(ctx, json_output):
        emit_json(
            {
                "rig": name,
                "active_version": active,
                "versions": [
                    {
                        "version": c.version,
                        "status": c.status,
                        "created_at": c.provenance.created_at,
                        "content_sha256": c.content_sha256,
                        "lint_errors": sum(f.severity == "error" for f in c.lint),
                        "handeye": [
                            {"edge": f"{h.parent_frame}:{h.child_frame}", "status": h.status}
                            for h in c.handeye
                        ],
                        "lidar": [
                            {"edge": f"{h.parent_frame}:{h.child_frame}", "status": h.status} for h in c.lidar
                        ],
                        "imu": [
                            {"edge": f"{h.parent_frame}:{h.child_frame}", "status": h.status} for h in c.imu
                        ],
                    }
                    for c in cals
                ],
                "events": [e.model_dump(mode="json") for e in events],
            }
        )
        return
    say(f"rig {name} history (active: {active if active is not None else 'none'})")
    for c in cals:
        base = named_list([f"{p.a}-{p.b} {p.baseline_mm:.3f} mm" for p in c.pairs], 3)
        hand_eye = "".join(f"; hand-eye {h.parent_frame} -> {h.child_frame} {h.status}" for h in c.handeye)
        hand_eye += "".join(f"; lidar {h.parent_frame} -> {h.child_frame} {h.status}" for h in c.lidar)
        hand_eye += "".join(f"; imu {h.parent_frame} -> {h.child_frame} {h.status}" for h in c.imu)
        say(
            f"  {c.version:>3} {c.status:<8} {'*' if c.version == active else ' '} "
            f"{c.provenance.created_at:%Y-%m-%d %H:%M}  {base}{hand_eye}"
        )
    for e in events:
        say(f"  event {e.event_id}: {e.kind} -> {e.version} by {e.actor} at {e.station}: {e.reason}")


@rig_app.command("show")
def show(
    ctx: typer.Context, ref: Annotated[str, typer.Argument(metavar="RIG[@N]")], json_output: JsonFlag = False
) -> None:
    """One rig calibration in full."""
    from calibctl.workflows.rig import rig_lint

    cal = rig_lint.show(state(ctx).settings(), ref)
    if wants_json(ctx, json_output):
        emit_json(cal)
        return
    _, active, _ = rig_lint.history(state(ctx).settings(), cal.rig)
    print_rig_calibration(cal, cal.version == active)


@rig_app.command("rollback")
def rollback(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(metavar="RIG")],
    to: Annotated[int, typer.Option("--to", help="Accepted version to make active.")],
    reason: Annotated[str, typer.Option("--reason", help="Why.")],
    expect_active: Annotated[
        int | None,
        typer.Option(
            "--expect-active", help="The active rig version you decided on; refused if it has changed since."
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Make an earlier accepted rig version active again (appends an event). A newer version stored or
    activated by someone else in the meantime makes it refuse (exit 2) instead of undoing it. A version
    that is active already is a success that writes nothing."""
    from calibctl.workflows.rig import rig_lint

    event = rig_lint.rollback(state(ctx).settings(), name, to, reason, expected_active=expect_active)
    if event is None:
        if wants_json(ctx, json_output):
            emit_json({"rig": name, "version": to, "already_active": True})
        else:
            say(f"rig {name}: version {to} is already the active version; nothing written")
        return
    if wants_json(ctx, json_output):
        emit_json(event)
        return
    say(f"rig {name}: active version {event.previous_version} -> {event.version} ({reason})")


@rig_app.command("export")
def export(
    ctx: typer.Context,
    ref: Annotated[str, typer.Argument(metavar="RIG[@N]")],
    fmt: Annotated[
        str,
        typer.Option(
            "--format",
            help="json, opencv, ros (one camera_info per camera, -o DIR), tf, "
            "urdf (a <robot> ROS loads), urdf-joints (the joints alone, to paste into your "
            "URDF), kalibr (camchain, with T_cam_imu and timeshift_cam_imu when the rig has an IMU), "
            "kalibr-imu (imu.yaml of the camera-IMU edge), kalibr-target (target.yaml of that edge's board), "
            "bundle (all of them + manifest.json, -o DIR), "
            "or lut (each stereo pair's rectification maps for cv2.remap, -o DIR).",
        ),
    ] = "json",
    out: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            help="Write to this file (ros: a folder or 'DIR/{camera}.yaml'; bundle, lut: a new folder).",
            show_default=False,
        ),
    ] = None,
    pair: Annotated[
        str | None,
        typer.Option(
            "--pair",
            help="Stereo formats: the right camera (default: the second member).",
            show_default=False,
        ),
    ] = None,
    frame: Annotated[
        list[str] | None,
        typer.Option(
            "--frame",
            help="SERIAL=ROS_FRAME: the robot's name of a frame "
            "(repeat), e.g. LEFT-01=front_left_camera_optical_frame; default "
            "left_01_optical_frame.",
            show_default=False,
        ),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite -o (bundle, lut: only a folder calibctl wrote).")
    ] = False,
    allow_rejected: Annotated[
        bool,
        typer.Option(
            "--allow-rejected", help="Export a rejected version (to inspect it; a robot must not load it)."
        ),
    ] = False,
    allow_stale: Annotated[
        bool,
        typer.Option(
            "--allow-stale",
            help="Export a version `rig lint` fails for a stale "
            "member (to inspect it; a robot must not load it).",
        ),
    ] = False,
    edge: Annotated[
        str | None,
        typer.Option(
            "--edge",
            help="FROM:TO: one hand-eye, LiDAR or IMU edge, its result document (json) or /tf_static (tf).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """What a robot loads: OpenCV stereo FileStorage, ROS camera_info per camera, tf_static, URDF, Kalibr, the
    whole bundle, or the stereo pairs' rectification maps (lut). Exit 1 when `rig lint` fails the version
    now for a stale member (unless --allow-stale).

    Frames are ROS names (REP 103 optical frames, docs/conventions.md): --frame maps a serial, the default
    is derived from it (LEFT-01 -> left_01_optical_frame). urdf is a complete <robot name="RIG">; tf and urdf
    carry the whole tree, hand-eye edges included; the stereo formats and Kalibr the cameras."""
    from calibctl.workflows.rig import rig_export

    settings = state(ctx).settings()
    if fmt in rig_export.FILE_FORMATS and edge is None:
        for path in rig_export.export_files(
            settings,
            ref,
            fmt,
            out,
            force=force,
            pair=pair,
            allow_rejected=allow_rejected,
            allow_stale=allow_stale,
            frames=frame or [],
        ):
            say(f"wrote {path}")
        return
    text = rig_export.export(
        settings,
        ref,
        fmt,
        out,
        force=force,
        pair=pair,
        allow_rejected=allow_rejected,
        allow_stale=allow_stale,
        edge=edge,
        frames=frame or [],
    )
    if out is None:
        print(text, end="")
    else:
        say(f"wrote {out}")


@rig_app.command("import")
def import_(
    ctx: typer.Context,
    path: Annotated[
        Path,
        typer.Argument(
            metavar="FILE",
            help="A rig version exported with `rig export --format json`, "
            "or a bundle folder (or its manifest.json).",
        ),
    ],
    activate: Annotated[
        bool | None,
        typer.Option(
            "--activate/--no-activate",
            show_default=False,
            help="Make it active (default: when this store accepts it, every member is active here and, in "
            "a store "
            "with keys, a trusted key signed it; --activate overrides the signature rule, recorded).",
        ),
    ] = None,
    require_signature: Annotated[
        bool,
        typer.Option(
            "--require-signature", help="Refuse a rig version not signed by a trusted key (exit 2)."
        ),
    ] = False,
    trusted_keys: Annotated[
        Path | None,
        typer.Option(
            "--trusted-keys",
            metavar="DIR",
            help="Folder of trusted public keys (*.pem); default: the trusted_keys setting.",
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Bring a rig version exported by another store into this one: its hash (edited: exit 1) and signature
    are checked, its members must be in this store (the same versions, or imports of them: `calibctl import`
    them first), and its lint, verdict and version are this store's. A rejected or stale import is never
    active."""
    from calibctl.workflows.rig import rig_import

    out = rig_import.import_rig_file(
        state(ctx).settings(),
        path,
        activate=activate,
        require_signature=require_signature,
        trusted_keys=trusted_keys,
    )
    cal = out.calibration
    if wants_json(ctx, json_output):
        emit_json(
            {
                "calibration": cal.model_dump(mode="json"),
                "source": out.source_ref,
                "source_status": out.source_status,
                "active": out.active,
                "already_imported": out.already_imported,
                "stale": [f.model_dump(mode="json") for f in out.stale],
                "held_back": out.held_back,
                "notes": [f.model_dump(mode="json") for f in out.notes],
            }
        )
    else:
        again = "already stored as" if out.already_imported else "imported as"
        say(
            f"{again} {cal.ref} ({cal.status} by this store's lint, "
            f"{'active' if out.active else 'not active'}; "
            f"source {out.source_ref} was {out.source_status}; sha256 {cal.content_sha256[:12]})"
        )
        if not out.already_imported:
            print_findings([f for f in [*cal.lint, *out.stale] if f.severity == "error"])
        print_findings(out.notes)
        if out.held_back:
            say(out.held_back)
    if (
        activate is not False and out.held_back is None and not out.already_imported and not out.active
    ):  # asked to make it active; this store says no
        raise typer.Exit(EXIT_VERDICT_FAIL)


def register(app: typer.Typer) -> None:
    """Add the ``rig`` command group to the root app."""
    app.add_typer(rig_app, name="rig")
