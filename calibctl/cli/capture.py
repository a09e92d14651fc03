"""calibctl capture commands: capture, calibrate (capture then solve), prune, synth."""

from __future__ import annotations

from collections import Counter
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

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
from calibctl.cli.render import emit_json, shown, stderr, stdout
from calibctl.cli.report import print_gates
from calibctl.cli.solve import (
    ActivateOption,
    DropOutliersOption,
    ModelOption,
    render_outcome,
)
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.errors import EXIT_VERDICT_FAIL

if TYPE_CHECKING:
    from collections.abc import Callable
    from typing import TypeVar

    from calibctl.artifacts.check import DistanceCheck
    from calibctl.config import Settings
    from calibctl.workflows.camera import capture as capture_workflow
    from calibctl.workflows.camera.capture import CaptureObserver

    R = TypeVar("R")

# The workflows (OpenCV, the store, SQLAlchemy, alembic) are imported inside the commands, so that
# `calibctl --help`, `--version` and the other commands do not pay for them.

SerialOption = Annotated[str, typer.Option("--serial", help="Camera serial number.", show_default=False)]
BoardOption = Annotated[
    str, typer.Option("--board", help="Registered board NAME or NAME@REV.", show_default=False)
]
SourceOption = Annotated[
    str,
    typer.Option(
        "--source",
        show_default=False,
        help="A folder of images; a quoted glob ('shots/left*.jpg', relative to the working directory); a "
        "list file "
        "(.txt/.lst/.list: one image path per line, relative to the list file's folder, # comments); a video "
        "file; or a camera (/dev/videoN or an index such as 0).",
    ),
]
MaxViewsOption = Annotated[
    int | None,
    typer.Option(
        "--max-views",
        show_default=False,
        help="Video/camera: stop once the gates pass and this many views are kept (camera default: as soon "
        "as "
        "the gates pass; a video file is otherwise read to the end).",
    ),
]
DurationOption = Annotated[
    float | None,
    typer.Option(
        "--duration", show_default=False, help="Video/camera: stop after S seconds (video time for a file)."
    ),
]
JsonOption = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
ImageCircleOption = Annotated[
    str | None,
    typer.Option(
        "--image-circle",
        metavar="CX,CY,R",
        show_default=False,
        help="The image circle of a circular fisheye, pixels: coverage counts only the cells mostly inside "
        "it "
        "(default: found in the frames, none for a pinhole or full-frame lens).",
    ),
]


class Scenario(StrEnum):
    good = "good"
    flat = "flat"
    centre = "centre"
    one_direction = "one-direction"
    video = "video"


class Pattern(StrEnum):
    chessboard = "chessboard"
    charuco = "charuco"
    aprilgrid = "aprilgrid"


def register(app: typer.Typer) -> None:
    """Add this module's commands to the root app."""
    app.command("capture")(capture)
    app.command("calibrate")(calibrate)
    app.command("prune")(prune)
    register_synth(app)


def _early_settings(
    ctx: typer.Context, source: str, station: str | None, operator: str | None, jobs: int | None
) -> Settings:
    """The settings, and the detection pool's fork server started when ``source`` will need it: before the
    caller imports the capture workflow (its store, models), so the server's imports overlap with those."""
    from calibctl.workflows.camera.capture_sources import start_detection_early

    settings = state(ctx).settings(station=station, operator=operator, jobs=jobs)
    start_detection_early(source, settings.jobs)
    return settings


def _run_capture(settings: Settings, as_json: bool, run: Callable[[Settings, CaptureObserver], R]) -> R:
    from calibctl.cli.live_view import capture_observer  # subclasses the capture workflow's observer

    with capture_observer(as_json, settings.gates.min_views, None) as observer:
        return run(settings, observer)


def _outcome_table(result: capture_workflow.CaptureResult) -> Table:
    session = result.session
    tilts = {v.name: v for v in session.views}
    stream = session.source_kind in ("video", "camera")
    rows = [o for o in session.outcomes if o.status == "accepted"] if stream else session.outcomes
    table = Table(title=f"{'kept frames' if stream else 'images'} of {session.source}", title_justify="left")
    for col in ("image" if not stream else "frame", "status", "size", "corners", "tilt", "reason"):
        table.add_column(col)
    # an accepted view whose tilt could not be read: the observability gate's detail says why (else a blank
    # cell)
    unread = [
        str(w)
        for g in session.gates
        if g.gate == "observability" and isinstance(listed := (g.detail or {}).get("views_not_used"), list)
        for w in listed
    ]
    for o in rows:
        view = tilts.get(o.name)
        tilt = (
            ""
            if view is None or view.tilt_deg is None
            else (f"{view.tilt_deg:.0f} deg" + (f" {view.tilt_direction}" if view.tilt_direction else ""))
        )
        reason = o.reason or ""
        if view is not None and view.tilt_deg is None:
            why = next((w[len(o.name) + 2 :] for w in unread if w.startswith(f"{o.name}: ")), "")
            tilt, reason = "not read", reason or why
        style = "green" if o.status == "accepted" else "yellow"
        table.add_row(
            shown(o.name),
            f"[{style}]{o.status}[/{style}]",
            f"{o.image_size[0]}x{o.image_size[1]}" if o.image_size else "-",
            str(o.corners_found),
            tilt,
            escape(reason),
        )
    return table


def print_capture(result: capture_workflow.CaptureResult, model: str | None = None) -> None:
    """The per-image outcome table, the gate table with hints, and the session id; ``model``: the --model
    given (the gauge line says which lens it judged through, and that auto chose it)."""
    session = result.session
    stdout.print(_outcome_table(result))
    counts = Counter(o.status for o in session.outcomes)
    noun = "frames" if session.source_kind in ("video", "camera") else "images"
    stdout.print(
        f"{len(session.outcomes)} {noun} examined: " + ", ".join(f"{n} {s}" for s, n in counts.most_common())
    )
    stdout.print(f"stopped: {result.stop_reason}")
    print_gates(session.gates)
    style = "green" if result.passed else "red"
    size = f", {session.image_size[0]}x{session.image_size[1]}" if session.image_size else ""
    stdout.print(
        f"session [bold]{session.session_id}[/bold] [{style}]{session.status}[/{style}]: "
        f"{len(session.views)} views of {session.serial} with board {session.board.ref}{size}"
    )
    stdout.print(f"{result.images_stored} image(s) kept in {result.image_dir}")
    if result.distance is not None:
        print_distance(result.distance)
        if result.gauge_lens is not None:
            chosen = ", the model --model auto chooses for this session" if model == "auto" else ""
            stdout.print(f"  gauged through {result.gauge_lens}{chosen}", markup=False, highlight=False)
    if session.status != "accepted":
        reasons = ", ".join(g.reason for g in session.gates if g.reason)
        stdout.print(
            f"[red]rejected[/red] ({reasons}); stored for the record. Follow the hints and capture again."
        )
    if result.interrupted:
        stderr.print(f"Interrupted: {result.stop_reason}.")


def print_distance(d: DistanceCheck) -> None:
    """The gauge line (--reference-distance) and, when it failed, the seed's explanation."""
    from calibctl.workflows.camera.distance_gauge import distance_reason

    verdict = "pass" if d.passed else "[red]FAIL[/red]"
    stdout.print(
        f"distance {d.recovered_m:.4f} m vs surveyed {d.reference_m:.4f} m: ratio {d.ratio:.4f} "
        f"(needs {d.ratio_limits[0]}-{d.ratio_limits[1]}) {verdict}",
        highlight=False,
    )
    if not d.passed:
        stdout.print(
            f"-> {distance_reason(d)}; the session carries the failed gauge: its solve is rejected unless "
            "--override-gauge REASON says why it does not apply",
            markup=False,
            highlight=False,
        )


ReferenceSourceOption = Annotated[
    str | None,
    typer.Option(
        "--reference-source",
        show_default=False,
        help="Folder, glob or list of pictures taken with the board in that fixture.",
    ),
]
GaugeModelOption = Annotated[
    str | None,
    typer.Option(
        "--model",
        show_default=False,
        help="With --reference-distance: the lens model the gauge solves the session with, the one `solve "
        "--model` "
        "will use (as there; default k1k2; auto gauges through the model auto chooses for the session). A "
        "fisheye needs fisheye or auto.",
    ),
]


def capture(
    ctx: typer.Context,
    board: BoardOption,
    source: Annotated[
        list[str],
        typer.Option(
            "--source",
            show_default=False,
            help="A folder of images; a quoted glob ('shots/left*.jpg', relative to the working "
            "directory); a list "
            "file (.txt/.lst/.list: one image path per line, relative to the list file's folder, # "
            "comments); a "
            "video file; or a camera (/dev/videoN or an index such as 0). With --rig, SERIAL=SRC once per "
            "member.",
        ),
    ],
    serial: Annotated[
        str | None, typer.Option("--serial", help="Camera serial number.", show_default=False)
    ] = None,
    station: StationOption = None,
    operator: OperatorOption = None,
    max_views: MaxViewsOption = None,
    duration: DurationOption = None,
    rig: Annotated[
        str | None,
        typer.Option(
            "--rig",
            help="Capture a registered rig instead (same as `calibctl rig "
            "capture`); the options of one camera (--serial, --image-circle, "
            "--reference-*, --max-views, --duration) are refused.",
            show_default=False,
        ),
    ] = None,
    image_circle: ImageCircleOption = None,
    reference_distance: ReferenceDistanceOption = None,
    reference_source: ReferenceSourceOption = None,
    model: GaugeModelOption = None,
    timestamps: RigTimestampsOption = None,
    time_tolerance_ms: RigTimeToleranceOption = None,
    jobs: JobsOption = None,
    json_output: JsonOption = False,
) -> None:
    """Detect the board in a folder, glob, list file, video or camera, run the capture gates and store the
    session.

    Exit 0 when every gate passes, 1 when a gate fails (the session is stored as rejected, with its
    reasons and hints) or the board distance misses --reference-distance (the metric scale is wrong),
    2 when the capture could not run (nothing is stored).
    """
    from calibctl.errors import UsageError

    if model is not None and reference_distance is None:
        raise UsageError(
            "--model on capture is the lens of the distance gauge; it needs --reference-distance",
            "a capture is not solved: give --model to `calibctl solve` or use `calibctl calibrate`",
        )
    if rig is not None:
        from calibctl.cli.rig import capture as capture_rig

        one_camera = {
            "--serial": serial,
            "--image-circle": image_circle,
            "--reference-distance": reference_distance,
            "--reference-source": reference_source,
            "--max-views": max_views,
            "--duration": duration,
        }
        given = [flag for flag, value in one_camera.items() if value is not None]
        if given:
            raise UsageError(
                f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to one camera, not to a "
                "rig (--rig)",
                "capture that camera on its own with --serial (its image circle, its "
                "distance gauge, a video or camera source)",
            )
        capture_rig(
            ctx,
            rig,
            source,
            board,
            timestamps=timestamps,
            time_tolerance_ms=time_tolerance_ms,
            station=station,
            operator=operator,
            jobs=jobs,
            json_output=json_output,
        )
        return
    if timestamps is not None or time_tolerance_ms is not None:
        raise UsageError(
            "--timestamps and --time-tolerance-ms pair the members of a rig: they need --rig RIG",
            hint="one camera's capture takes its frames in order",
        )
    if serial is None:
        raise UsageError("capture needs --serial SERIAL", hint="or capture a registered rig with --rig RIG")
    if len(source) != 1:
        raise UsageError(
            f"one camera takes one --source, got {len(source)}", hint="capture a rig with --rig RIG"
        )
    settings = _early_settings(ctx, source[0], station, operator, jobs)
    from calibctl.workflows.camera import capture as capture_workflow
    from calibctl.workflows.camera.distance_gauge import gauge_model, parse_reference_distance
    from calibctl.workflows.camera.image_circles import parse_image_circle

    as_json = wants_json(ctx, json_output)
    distance = None if reference_distance is None else parse_reference_distance(reference_distance)
    request = capture_workflow.CaptureRequest(
        serial,
        board,
        source[0],
        max_views,
        duration,
        image_circle=parse_image_circle(image_circle),
        reference_distance=distance,
        reference_source=reference_source,
        gauge_model=gauge_model(model),
    )
    result = _run_capture(
        settings, as_json, lambda settings, obs: capture_workflow.capture(settings, request, obs)
    )
    if as_json:
        emit_json(result.as_json())
    else:
        print_capture(result, model)
    if not result.passed:
        raise typer.Exit(EXIT_VERDICT_FAIL)


def calibrate(
    ctx: typer.Context,
    serial: SerialOption,
    board: BoardOption,
    source: SourceOption,
    station: StationOption = None,
    operator: OperatorOption = None,
    max_views: MaxViewsOption = None,
    duration: DurationOption = None,
    model: ModelOption = DEFAULT_MODEL,
    activate: ActivateOption = True,
    drop_outliers: DropOutliersOption = False,
    image_circle: ImageCircleOption = None,
    reference_distance: ReferenceDistanceOption = None,
    reference_source: ReferenceSourceOption = None,
    override_gauge: OverrideGaugeOption = None,
    jobs: JobsOption = None,
    json_output: JsonOption = False,
) -> None:
    """Capture, then solve the new session when its gates pass: one command from pictures to a calibration.

    Exit 0 when the gates pass and the calibration is accepted, 1 when a gate or lint rejects it, 2 when
    it could not run.
    """
    settings = _early_settings(ctx, source, station, operator, jobs)
    from calibctl.workflows.camera import capture as capture_workflow
    from calibctl.workflows.camera.distance_gauge import parse_reference_distance
    from calibctl.workflows.camera.image_circles import parse_image_circle

    as_json = wants_json(ctx, json_output)
    distance = None if reference_distance is None else parse_reference_distance(reference_distance)
    request = capture_workflow.CaptureRequest(
        serial,
        board,
        source,
        max_views,
        duration,
        image_circle=parse_image_circle(image_circle),
        reference_distance=distance,
        reference_source=reference_source,
    )
    result = _run_capture(
        settings,
        as_json,
        lambda settings, obs: capture_workflow.calibrate(
            settings,
            request,
            model=model,
            activate=activate,
            drop_outliers=drop_outliers,
            observer=obs,
            override_gauge=override_gauge,
        ),
    )
    solved = result.solve
    if as_json:
        emit_json(
            {
                "capture": result.capture.as_json(),
                "calibration": solved.artifact.model_dump(mode="json") if solved else None,
                "active": bool(solved and solved.active),
            }
        )
        if solved is None or solved.artifact.status != "accepted":
            raise typer.Exit(EXIT_VERDICT_FAIL)
        return
    print_capture(result.capture, model)
    if solved is None:
        failed = "the distance gauge" if result.capture.session.status == "accepted" else "the capture gates"
        stdout.print(f"[red]not solved[/red]: {failed} failed")
        raise typer.Exit(EXIT_VERDICT_FAIL)
    render_outcome(solved, as_json=False)


def prune(
    ctx: typer.Context,
    now: Annotated[
        str | None,
        typer.Option(
            "--now", show_default=False, help="Prune as of this ISO time (default: now; no zone means UTC)."
        ),
    ] = None,
    json_output: JsonOption = False,
) -> None:
    """Delete stored images whose retention has expired. Corners, sessions and calibrations are never
    touched."""
    from calibctl.workflows.camera import capture as capture_workflow

    when = capture_workflow.parse_now(now) if now is not None else None
    result = capture_workflow.prune(state(ctx).settings(), when)
    if wants_json(ctx, json_output):
        emit_json({"pruned": result.pruned, "image_dir": result.image_dir, "now": result.now.isoformat()})
        return
    stdout.print(
        f"pruned {result.pruned} expired image(s) from {result.image_dir} as of "
        f"{result.now.isoformat(timespec='seconds')}; corners, sessions and calibrations are kept"
    )


def register_synth(app: typer.Typer) -> None:
    """``calibctl synth``: ground-truth board photos (no store involved)."""

    @app.command("synth")
    def synth(
        ctx: typer.Context,
        out: Annotated[
            Path, typer.Argument(metavar="OUT", help="Output folder (created; must be empty unless --force).")
        ],
        scenario: Annotated[
            Scenario, typer.Option("--scenario", help="Which session to stage.")
        ] = Scenario.good,
        seed: Annotated[
            int, typer.Option("--seed", help="Random seed; the same seed gives the same files.")
        ] = 0,
        views: Annotated[
            int | None,
            typer.Option(
                "--views",
                help="Views to render (video: key poses). Default 12 (video: 8).",
                show_default=False,
            ),
        ] = None,
        size: Annotated[
            str, typer.Option("--size", help="Image size WxH; the seed's lens is scaled to it.")
        ] = "640x480",
        pattern: Annotated[
            Pattern,
            typer.Option(
                "--pattern",
                help="Board pattern: chessboard 9x6 inner corners, 25 mm; charuco 10x7 squares; aprilgrid "
                "6x6 tags of 30 mm, spacing 0.3.",
            ),
        ] = (Pattern.chessboard),
        force: Annotated[
            bool, typer.Option("--force", help="Write into a non-empty OUT, replacing earlier synth files.")
        ] = False,
        rig: Annotated[
            int | None,
            typer.Option(
                "--rig",
                help="Render a synchronised rig of N (2-4) cameras instead: OUT/CAMi/ folders "
                "and rig_truth.json (--views = frames, default 14).",
                show_default=False,
            ),
        ] = None,
        baseline_mm: Annotated[
            float | None,
            typer.Option(
                "--baseline-mm",
                help="With --rig: the spacing of neighbouring cameras (default 60-120 mm, drawn per camera).",
                show_default=False,
            ),
        ] = None,
        fisheye: Annotated[
            float | None,
            typer.Option(
                "--fisheye",
                metavar="FOV_DEG",
                help="Render through an equidistant fisheye lens of this field "
                "of view (60-190 deg; scenario good), truth k1..k4 in truth.json.",
                show_default=False,
            ),
        ] = None,
        full_frame: Annotated[
            bool,
            typer.Option(
                "--full-frame",
                help="With --fisheye: the field of view spans the image diagonal instead of an image circle.",
            ),
        ] = False,
        json_output: Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")] = False,
    ) -> None:
        """Render a synthetic capture session through a known camera and write truth.json beside it.

        Scenarios: good (passes every gate), flat (tilt < 5 deg), centre (board only in the middle),
        one-direction (every tilt toward the right), video (an MJPG .avi of a hand-held sweep with pauses).
        """
        from calibctl.workflows.synth import synth as synth_workflow

        if rig is None and baseline_mm is not None:
            from calibctl.errors import UsageError

            raise UsageError(
                "--baseline-mm places the cameras of a rig; it needs --rig N",
                "e.g. calibctl synth OUT --rig 2 --baseline-mm 75",
            )
        if rig is not None:
            from calibctl.workflows.synth.synth_rig import run_synth_rig

            rig_result = run_synth_rig(
                out, rig, seed, views, synth_workflow.parse_size(size), baseline_mm, force
            )
            if wants_json(ctx, json_output):
                emit_json(rig_result.as_json())
                return
            per_camera = zip(rig_result.cameras, rig_result.photos_per_camera, strict=True)
            stdout.print(
                f"wrote {rig_result.n_frames} synchronised frames of a {rig}-camera rig "
                f"({', '.join(f'{c}: {n} photos' for c, n in per_camera)}) "
                f"and {rig_result.truth_path.name} to {rig_result.out_dir}"
            )
            return
        result = synth_workflow.run_synth(
            out,
            scenario.value,
            seed,
            views,
            synth_workflow.parse_size(size),
            pattern.value,
            force,
            fisheye,
            not full_frame,
        )
        if wants_json(ctx, json_output):
            emit_json(result.as_json())
            return
        what = "1 video" if scenario is Scenario.video else f"{len(result.files)} images"
        stdout.print(
            f"wrote {what} ({result.n_views} {'frames' if scenario is Scenario.video else 'views'}, "
            f"{result.image_size[0]}x{result.image_size[1]}, scenario {result.scenario}) "
            f"and {result.truth_path.name} to {result.out_dir}"
        )
