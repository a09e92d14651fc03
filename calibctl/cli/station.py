"""calibctl station: one warm process calibrating unit after unit (``workflows.station``)."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import JobsOption, OperatorOption, StationOption

if TYPE_CHECKING:
    from calibctl.workflows.station.station import UnitResult


def register(app: typer.Typer) -> None:
    """Add this module's commands to the root app."""
    app.command("station")(station)


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
    print(f"{result.serial}: {result.status.upper()} - {result.message}{numbers} ({result.unit_s:.2f} s)", flush=True)
    if result.hint and result.status not in ("pass",):
        print(f"  hint: {result.hint}", flush=True)


def station(
    ctx: typer.Context,
    board: Annotated[str, typer.Option("--board", help="Registered board NAME or NAME@REV.", show_default=False)],
    source_template: Annotated[str, typer.Option(
        "--source-template", show_default=False,
        help="Where each unit's pictures arrive, with {serial}: a folder (DIR/{serial}), a quoted glob or a list "
             "file.")],
    serials: Annotated[Path | None, typer.Option(
        "--serials", show_default=False, help="Read the serials from this file, one per line (default: stdin, "
        "where a barcode scanner types them).")] = None,
    model: Annotated[str, typer.Option("--model", help="Lens model of every unit's solve.")] = "k1k2",
    station_id: StationOption = None,
    operator: OperatorOption = None,
    jobs: JobsOption = None,
    json_output: Annotated[bool, typer.Option("--json", help="One JSON object per unit on stdout (for a line "
                                              "controller).")] = False,
) -> None:
    """Calibrate unit after unit in one warm process: read a serial, capture DIR/{serial}, solve, store, print the
    verdict, wait for the next.

    A bad serial, a serial done twice in this run, a missing folder or an unknown board is a line with status
    "error", and the station goes on. Ctrl-C while waiting ends it (exit 0); while a unit's images are detected it
    cancels that unit (nothing stored) and the station waits for the next serial. Exit 0 when the serials end;
    2 when the station cannot start (bad template, serials file unreadable, database unavailable).
    """
    from calibctl.workflows.station import station as station_workflow

    as_json = wants_json(ctx, json_output)
    request = station_workflow.StationRequest(board, source_template, model)
    station_workflow.check_request(request)
    lines = _file_serials(serials) if serials is not None else _stdin_serials(sys.stdin.isatty() and not as_json)
    settings = state(ctx).settings(station=station_id, operator=operator, jobs=jobs)
    station_workflow.warm_up(settings)
    summary = station_workflow.run_station(settings, request, lines, lambda r: _say(r, as_json))
    if summary.interrupted:
        print(f"station stopped (Ctrl-C) after {len(summary.units)} unit(s)", file=sys.stderr, flush=True)
