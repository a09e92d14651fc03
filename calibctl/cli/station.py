"""calibctl station: one warm process calibrating unit after unit (``workflows.station``)."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import JobsOption, OperatorOption, StationOption
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL

if TYPE_CHECKING:
    from calibctl.config import Settings
    from calibctl.store.spool import Spool
    from calibctl.workflows.camera.capture import CaptureObserver
    from calibctl.workflows.station.station import LiveCamera, UnitResult
    from calibctl.workflows.station.watch import WatchRule


station_app = typer.Typer(
    name="station",
    invoke_without_command=True,
    rich_markup_mode=None,
)
JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
SpoolOption = Annotated[
    Path | None,
    typer.Option(
        "--spool",
        show_default=False,
        help="The station's offline spool, a SQLite file (default: calibctl-spool.sqlite "
        "in the station file's folder, else the SQLite store's, else the current folder).",
    ),
]


def register(app: typer.Typer) -> None:
    """Add this module's commands to the root app."""
    app.add_typer(station_app, name="station")


def _stdin_serials(prompt: bool) -> Iterator[str]:
    while True:
        if prompt:
            print("serial> ", end="", file=sys.stderr, flush=True)
        line = sys.stdin.readline()
        if not line:
            return
        yield line


def _file_serials(path: Path) -> list[str]:
    from calibctl import bounded
    from calibctl.errors import FileSystemError, InputError

    try:
        return bounded.read_text(path, "read the serials file").splitlines()
    except FileSystemError as exc:
        raise InputError(exc.message, "--serials names a UTF-8 text file, one serial per line") from exc


def _say(result: UnitResult, as_json: bool) -> None:
    if as_json:
        print(json.dumps(result.as_json()), flush=True)
        return
    numbers = "" if result.rms_px is None else f", RMS {result.rms_px:.3f} px, {result.views} views"
    after = (
        ""
        if result.after_last_image_s is None
        else f", {result.after_last_image_s:.2f} s after the last picture"
    )
    print(
        f"{result.serial}: {result.status.upper()} - {result.message}{numbers} ({result.unit_s:.2f} "
        f"s{after})",
        flush=True,
    )
    if result.hint and result.status not in ("pass",):
        print(f"  hint: {result.hint}", flush=True)


@station_app.callback(invoke_without_command=True)
def station(
    ctx: typer.Context,
    board: Annotated[
        str | None,
        typer.Option("--board", help="Registered board NAME or NAME@REV (required).", show_default=False),
    ] = None,
    source_template: Annotated[
        str | None,
        typer.Option(
            "--source-template",
            show_default=False,
            help="Where each unit's pictures arrive, with {serial}: a folder (DIR/{serial}), a quoted glob "
            "or a list "
            "file (this or --camera).",
        ),
    ] = None,
    camera: Annotated[
        str | None,
        typer.Option(
            "--camera",
            show_default=False,
            help="Capture each unit live from this camera (/dev/videoN or an index such as 0): the unit's "
            "own camera, "
            "plugged into the station (this or --source-template).",
        ),
    ] = None,
    max_views: Annotated[
        int | None,
        typer.Option(
            "--max-views",
            show_default=False,
            help="--camera: a unit's capture stops once the gates pass and this many views are kept "
            "(default: as soon "
            "as the gates pass).",
        ),
    ] = None,
    duration: Annotated[
        float | None,
        typer.Option(
            "--duration",
            show_default=False,
            help="--camera: a unit's capture stops after S seconds and is judged with the views kept.",
        ),
    ] = None,
    serials: Annotated[
        Path | None,
        typer.Option(
            "--serials",
            show_default=False,
            help="Read the serials from this file, one per line (default: stdin, "
            "where a barcode scanner types them).",
        ),
    ] = None,
    model: Annotated[str, typer.Option("--model", help="Lens model of every unit's solve.")] = DEFAULT_MODEL,
    station_id: StationOption = None,
    operator: OperatorOption = None,
    jobs: JobsOption = None,
    json_output: Annotated[
        bool, typer.Option("--json", help="One JSON object per unit on stdout (for a line controller).")
    ] = False,
    spool: SpoolOption = None,
    watch: Annotated[
        bool,
        typer.Option(
            "--watch",
            help="After each serial, wait for the unit's pictures in its folder and detect each as it lands "
            "(needs --views and/or --done-file).",
        ),
    ] = False,
    views: Annotated[
        int | None,
        typer.Option(
            "--views", show_default=False, help="--watch: the unit is complete with this many pictures."
        ),
    ] = None,
    done_file: Annotated[
        str | None,
        typer.Option(
            "--done-file",
            show_default=False,
            help="--watch: the unit is complete when the camera app writes this file "
            "into its folder (after the last picture).",
        ),
    ] = None,
    # None: the watch rule's own default (WatchRule), which the help names (a test keeps the two equal)
    settle_s: Annotated[
        float | None,
        typer.Option(
            "--settle-s",
            show_default=False,
            help="--watch: a picture is complete when its size has not changed for "
            "this long (default 0.25 s); 0 when the camera app renames each picture into place.",
        ),
    ] = None,
    unit_timeout_s: Annotated[
        float | None,
        typer.Option(
            "--unit-timeout-s",
            show_default=False,
            help="--watch: a unit with no new picture for this long is an "
            "error line; nothing stored (default 120 s).",
        ),
    ] = None,
) -> None:
    """Calibrate unit after unit in one warm process: read a serial, capture DIR/{serial} (or the unit's
    camera, live, with --camera), solve, store, print the verdict, wait for the next.

    A bad serial, a serial done twice in this run, a missing folder or an unknown board is a line with status
    "error", and the station goes on. Ctrl-C while waiting ends it (exit 0); while a unit's images are
    detected it cancels that unit (nothing stored) and the station waits for the next serial. With --watch the
    station waits, after each serial, for the unit's pictures in DIR/{serial} and detects each as it lands
    (complete: renamed into place, or its size unchanged for --settle-s); the unit is captured when --views
    pictures are there or the camera app wrote --done-file, and its line adds the time from the last picture
    in to the verdict. With --camera each unit is captured live (the live view on stderr says what the gates
    still need) until the gates pass, and stored whole once its stream is over; a camera that cannot be opened
    or is unplugged mid-unit is an error line, nothing stored. With the store unreachable each unit is
    calibrated into the spool (status "queued") and stored, in order, when the store is back (status "synced",
    with its version). Exit 0 when the serials end; 2 when the station cannot start (bad template, serials
    file unreadable, another station's or store's spool).
    """
    if ctx.invoked_subcommand is not None:
        return
    from calibctl.errors import UsageError
    from calibctl.workflows.station import station as station_workflow

    if board is None or (source_template is None and camera is None):
        raise UsageError(
            "calibctl station needs --board and --source-template (or --camera)",
            "e.g. calibctl station --board A17 --source-template /data/shots/{serial}, or --camera "
            "/dev/video0; or a sub-command: calibctl station status | sync | set-aside",
        )
    as_json = wants_json(ctx, json_output)
    watching = _watch_rule(watch, views, done_file, settle_s, unit_timeout_s)
    live = _live_camera(camera, max_views, duration)
    request = station_workflow.StationRequest(board, source_template, model, spool, watching, live)
    station_workflow.check_request(request)
    lines = (
        _file_serials(serials) if serials is not None else _stdin_serials(sys.stdin.isatty() and not as_json)
    )
    settings = state(ctx).settings(station=station_id, operator=operator, jobs=jobs)
    station_workflow.warm_up(settings, request)
    summary = station_workflow.run_station(
        settings,
        request,
        lines,
        lambda r: _say(r, as_json),
        _unit_display(live, as_json, settings.gates.min_views),
    )
    if summary.interrupted:
        print(f"station stopped (Ctrl-C) after {len(summary.units)} unit(s)", file=sys.stderr, flush=True)


def _live_camera(camera: str | None, max_views: int | None, duration: float | None) -> LiveCamera | None:
    from calibctl.errors import UsageError
    from calibctl.workflows.station.station import LiveCamera

    if camera is not None:
        return LiveCamera(camera, max_views, duration)
    if max_views is not None or duration is not None:
        raise UsageError(
            "--max-views and --duration say when a unit's live capture stops; they need --camera",
            "add --camera DEVICE, or leave them out to capture each unit's folder",
        )
    return None


def _unit_display(live: LiveCamera | None, as_json: bool, min_views: int) -> Callable[[], CaptureObserver]:
    """What each unit shows while it runs: the live view of a camera unit (what the gates still need), nothing
    for a folder (its line comes within seconds)."""
    from calibctl.cli.live_view import capture_observer
    from calibctl.workflows.camera.capture import CaptureObserver

    if live is None:
        return CaptureObserver
    return lambda: capture_observer(
        as_json, min_views, live.max_views, "Ctrl-C: cancel this unit, nothing stored"
    )


def _watch_rule(
    watch: bool,
    views: int | None,
    done_file: str | None,
    settle_s: float | None,
    unit_timeout_s: float | None,
) -> WatchRule | None:
    from calibctl.errors import UsageError
    from calibctl.workflows.station.watch import WatchRule

    waits = {
        name: value
        for name, value in (("settle_s", settle_s), ("unit_timeout_s", unit_timeout_s))
        if value is not None
    }
    if watch:
        return WatchRule(views, done_file, **waits)
    if views is not None or done_file is not None:
        raise UsageError(
            "--views and --done-file say when a watched unit is complete; they need --watch",
            "add --watch, or leave them out to capture each unit's folder as it is when the serial is read",
        )
    if waits:
        raise UsageError(
            "--settle-s and --unit-timeout-s say how long a watched unit's pictures are waited for; "
            "they need --watch",
            "add --watch and --views N or --done-file NAME, or leave them out",
        )
    return None


@contextmanager
def _spool_of(
    ctx: typer.Context,
    spool: Path | None,
    station_id: str | None,
    *,
    operator: str | None = None,
    sign: bool = True,
) -> Iterator[tuple[Settings, Spool]]:
    """The settings and this station's existing spool (exit 2 when it is missing, another station's or
    store's)."""
    from calibctl.workflows.station import sync as sync_workflow

    settings = state(ctx).settings(station=station_id, operator=operator)
    with sync_workflow.open_spool(settings, spool, create=False, sign=sign) as opened:
        yield settings, opened


@station_app.command("status")
def status(
    ctx: typer.Context,
    spool: SpoolOption = None,
    station_id: StationOption = None,
    json_output: JsonFlag = False,
) -> None:
    """What the station's spool holds: the units queued while the store was away (oldest first, each checked
    as the sync checks it: its sha256, and its signature when the station has a signing key), the records set
    aside and how many were synced. Exit 0; 2 when the spool is missing or another station's."""
    from calibctl.workflows.station.sync import status as spool_status

    with _spool_of(ctx, spool, station_id, sign=False) as (_, opened):
        found = spool_status(opened)
    if wants_json(ctx, json_output):
        print(json.dumps(found.as_json()), flush=True)
        return
    print(
        f"spool {found.path} (station {found.station}, store {found.store}): {len(found.queued)} queued, "
        f"{found.synced} synced, {len(found.set_aside)} set aside"
    )
    for q in found.queued:
        mark = (
            ""
            if q.intact
            else (
                f"\n    REFUSED: it {q.problem}; the sync stops here (calibctl station set-aside "
                f"{q.seq} --reason TEXT lets the records after it sync)"
            )
        )
        print(
            f"  #{q.seq} {q.serial} session {q.session_id} queued {q.queued_at[:19]}: {q.verdict}, "
            f"{q.images} image(s){mark}"
        )
    for n in found.missing:
        print(
            f"  #{n} MISSING: the record was deleted from the spool; the sync stops before it (restore the "
            f"spool, or calibctl station set-aside {n} --reason TEXT)"
        )
    for a in found.set_aside:
        print(
            f"  #{a.seq} {a.serial} session {a.session_id} queued {a.queued_at[:19]}: SET ASIDE "
            f"{a.set_aside_at[:19]} by {a.operator}: {a.reason} ({a.images} image(s) kept; never synced)"
        )


@station_app.command("sync")
def sync_command(
    ctx: typer.Context,
    spool: SpoolOption = None,
    station_id: StationOption = None,
    json_output: JsonFlag = False,
) -> None:
    """Store the spool's queued units in the store, in the order they were calibrated, each getting the
    serial's next version there (signed with the station's key when one is configured). Run again after a
    kill: nothing is lost or stored twice. Exit 0 when the queue is empty; 1 when a record was changed (it and
    the ones after it stay queued); 2 when the store is still away, another process is syncing, or the spool
    is another station's or store's."""
    from calibctl.workflows.station.sync import sync

    as_json = wants_json(ctx, json_output)
    with _spool_of(ctx, spool, station_id) as (settings, opened):
        done = sync(settings, opened)
    for unit in done.synced:
        if as_json:
            print(json.dumps(unit.as_json()), flush=True)
        else:
            what = (
                "rejected capture session"
                if unit.version is None
                else (f"v{unit.version} {unit.status}{', active' if unit.active else ''}")
            )
            print(
                f"{unit.serial}: spool record {unit.seq} stored as {what}"
                f"{' (it was in the store already)' if unit.already else ''}",
                flush=True,
            )
    if done.error is not None:
        raise type(done.error)(
            f"{done.error.message} ({len(done.synced)} synced, {done.left} still queued)", done.error.hint
        )
    if not as_json:
        print(f"{len(done.synced)} unit(s) synced, {done.left} queued", file=sys.stderr, flush=True)


@station_app.command("set-aside")
def set_aside_command(
    ctx: typer.Context,
    record: Annotated[
        int,
        typer.Argument(help="The spool record's number (#N in calibctl station status).", show_default=False),
    ],
    reason: Annotated[
        str,
        typer.Option(
            "--reason",
            help="Why it is not synced; kept in the spool with the time and the operator.",
            show_default=False,
        ),
    ],
    spool: SpoolOption = None,
    station_id: StationOption = None,
    operator: OperatorOption = None,
    json_output: JsonFlag = False,
) -> None:
    """Set a queued spool record aside - one the sync refuses (changed, unsigned, an image changed), or a unit
    scrapped - so the records behind it sync. It stays in the spool with its images, the reason, the time and
    the operator (listed by calibctl station status), and is never synced: its unit gets no version. Exit 0; 2
    for an unknown, synced or already set-aside record, no reason, or a sync running."""
    from calibctl.workflows.station.sync import set_aside

    with _spool_of(ctx, spool, station_id, operator=operator, sign=False) as (settings, opened):
        done = set_aside(settings, opened, record, reason)
        path = opened.path
    if wants_json(ctx, json_output):
        print(json.dumps(done.as_json()), flush=True)
        return
    unit = done.unit
    print(
        f"{unit.serial}: spool record {unit.seq} (session {unit.session_id}) set aside by {unit.operator}: "
        f"{unit.reason}",
        flush=True,
    )
    print(
        f"kept in {path} with its {unit.images} image(s), never synced; {done.queued} record(s) still queued "
        "(calibctl station sync stores them)",
        file=sys.stderr,
        flush=True,
    )
