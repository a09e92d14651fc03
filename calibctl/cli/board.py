"""calibctl board add | list | show: the registry of calibration targets and their measured square size."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import pair_mm
from calibctl.cli.render import emit_json, plain, shown, stderr, stdout

if TYPE_CHECKING:
    from calibctl.artifacts.board import BoardRevision


class BoardKind(StrEnum):
    chessboard = "chessboard"
    charuco = "charuco"
    aprilgrid = "aprilgrid"


def say(line: str) -> None:
    """One result line on stdout, never wrapped or interpreted as markup (it holds URLs and user text)."""
    stdout.print(plain(line), soft_wrap=True, markup=False, highlight=False)


JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]

board_app = typer.Typer(
    name="board",
    help="Register calibration boards (square size measured, with provenance) and look them up.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


def _mm(value_m: float | None) -> str:
    if value_m is None:
        return "-"
    mm = value_m * 1000
    # three decimals read a caliper; a length under 1 um keeps 3 significant digits instead of "0.000 mm"
    return f"{mm:.3f} mm" if mm >= 0.001 else f"{mm:.3g} mm"


def square_text(board: BoardRevision) -> str:
    m = board.measurement
    if m.status == "nominal":
        return f"{_mm(m.square_size_m)} NOMINAL (not measured)"
    text = f"{_mm(m.square_size_m)} ± {_mm(m.uncertainty_m)} (1σ)"
    if m.span is not None:
        unit = "tags" if board.kind == "aprilgrid" else "squares"
        return text + f", span {_mm(m.span.span_m)} over {m.span.squares} {unit} agrees"
    return text + (" (single measurement)" if m.status == "measured-single" else "")


def pattern_text(board: BoardRevision) -> str:
    if board.kind == "aprilgrid":
        return (
            f"aprilgrid {board.cols // 2}x{board.rows // 2} tags ({board.cols}x{board.rows} corners), "
            f"{board.dictionary}, spacing {board.tag_spacing:g} of the tag"
        )
    text = f"{board.kind} {board.cols}x{board.rows} inner corners"
    if board.kind == "charuco":
        text += f", markers {_mm(board.marker_size_m)} {board.dictionary}"
        text += ", inverted (white markers on black)" if board.inverted else ""
        text += ", legacy layout (OpenCV < 4.6)" if board.legacy_pattern else ""
    return text


def print_board(board: BoardRevision, revisions: list[int] | None = None) -> None:
    m = board.measurement
    say(f"board {board.ref}: {pattern_text(board)}")
    say(f"  {'tag size ' if board.kind == 'aprilgrid' else 'square size'}   {square_text(board)}")
    if m.status != "nominal":
        say(f"  measured      with {m.instrument} by {m.measured_by} on {m.measured_on}")
        if m.evidence_sha256:
            say(f"  evidence      {m.evidence_name} sha256 {m.evidence_sha256}")
    if m.span is not None:
        say(f"  span          {_mm(m.span.span_m)} ± {_mm(m.span.uncertainty_m)} with {m.span.instrument}")
    if board.backing is not None:
        b = board.backing
        say(
            f"  backing board {_mm(b.width_m)} x {_mm(b.height_m)}, pattern offset "
            f"{_mm(b.pattern_offset_m[0])}, "
            f"{_mm(b.pattern_offset_m[1])}"
        )
    say(f"  registered    {board.created_at.isoformat()[:19].replace('T', ' ')} UTC by {board.created_by}")
    if board.note:
        say(f"  note          {board.note}")
    if revisions and len(revisions) > 1:
        say(f"  revisions     {', '.join(str(r) for r in revisions)}")


def _pair_mm(text: str | None, option: str) -> tuple[float, float] | None:
    return None if text is None else pair_mm(text, option)


@board_app.command("add")
def add(
    ctx: typer.Context,
    name: Annotated[
        str,
        typer.Argument(
            metavar="NAME", help="Board name, e.g. A17 (an existing name gets its next revision)."
        ),
    ],
    cols: Annotated[
        int | None, typer.Option("--cols", help="Inner corners per row (OpenCV patternSize width).")
    ] = None,
    rows: Annotated[int | None, typer.Option("--rows", help="Inner corners per column.")] = None,
    square_mm: Annotated[
        float | None, typer.Option("--square-mm", help="Square edge in millimetres.")
    ] = None,
    kind: Annotated[
        BoardKind | None,
        typer.Option(
            "--kind", help="Pattern type: chessboard (default), charuco, or aprilgrid (--from-kalibr's)."
        ),
    ] = None,
    tag_cols: Annotated[int | None, typer.Option("--tag-cols", help="AprilGrid: tags per row.")] = None,
    tag_rows: Annotated[int | None, typer.Option("--tag-rows", help="AprilGrid: tags per column.")] = None,
    tag_size_mm: Annotated[
        float | None,
        typer.Option("--tag-size-mm", help="AprilGrid: tag edge (outer edge of its black border), mm."),
    ] = None,
    tag_spacing: Annotated[
        float | None,
        typer.Option(
            "--tag-spacing", help="AprilGrid: gap between tags over the tag edge (Kalibr's tagSpacing)."
        ),
    ] = None,
    family: Annotated[
        str | None, typer.Option("--family", help="AprilGrid: AprilTag family (default 36h11, as Kalibr).")
    ] = None,
    from_kalibr: Annotated[
        Path | None,
        typer.Option("--from-kalibr", help="AprilGrid: Kalibr's target.yaml instead of the --tag-* options."),
    ] = None,
    uncertainty_mm: Annotated[
        float | None, typer.Option("--uncertainty-mm", help="One-sigma of the square size, mm.")
    ] = None,
    instrument: Annotated[
        str | None, typer.Option("--instrument", help="What measured it, e.g. 'Mitutoyo calipers'.")
    ] = None,
    measured_by: Annotated[str | None, typer.Option("--measured-by", help="Who measured it.")] = None,
    measured_on: Annotated[str | None, typer.Option("--measured-on", help="When, YYYY-MM-DD.")] = None,
    evidence: Annotated[
        Path | None, typer.Option("--evidence", help="Evidence file (photo, report); its sha256 is kept.")
    ] = None,
    marker_mm: Annotated[float | None, typer.Option("--marker-mm", help="ChArUco marker edge, mm.")] = None,
    dictionary: Annotated[
        str | None, typer.Option("--dictionary", help="ChArUco dictionary, e.g. DICT_5X5_100.")
    ] = None,
    inverted: Annotated[
        bool, typer.Option("--inverted", help="ChArUco printed white markers on black squares.")
    ] = False,
    legacy: Annotated[
        bool,
        typer.Option(
            "--legacy",
            help="ChArUco in the layout of OpenCV < 4.6 (boards with an even number of square rows).",
        ),
    ] = False,
    note: Annotated[
        str | None, typer.Option("--note", help="Free text, e.g. why it was re-measured.")
    ] = None,
    span_mm: Annotated[
        float | None,
        typer.Option(
            "--span-mm",
            help="Second measurement: outermost inner corner to outermost inner corner along the long "
            "side, mm.",
        ),
    ] = None,
    span_uncertainty_mm: Annotated[
        float | None, typer.Option("--span-uncertainty-mm", help="One-sigma of the span, mm.")
    ] = None,
    span_instrument: Annotated[
        str | None, typer.Option("--span-instrument", help="What measured the span.")
    ] = None,
    span_squares: Annotated[
        int | None,
        typer.Option(
            "--span-squares", help="Squares the span covers (default: inner corners along the long side - 1)."
        ),
    ] = None,
    backing_mm: Annotated[
        str | None,
        typer.Option(
            "--backing-mm",
            help="Backing board W,H in mm (W along the rows of --cols corners); camera-LiDAR targets.",
        ),
    ] = None,
    pattern_offset_mm: Annotated[
        str | None,
        typer.Option(
            "--pattern-offset-mm", help="Pattern centre minus backing centre X,Y in mm (pattern axes)."
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Register a board. Give the measurement (--uncertainty-mm, --instrument, --measured-by,
    --measured-on, optionally --evidence) and a second, independent one of the pattern's span (--span-mm,
    --span-uncertainty-mm, --span-instrument): a square size the span contradicts is refused. Both: measured;
    the square only: measured-single (lint warns); only --square-mm: nominal. An AprilGrid (Kalibr's target)
    takes --tag-cols, --tag-rows, --tag-size-mm and --tag-spacing, or --from-kalibr target.yaml; its tag
    size is measured like a square."""
    from calibctl.workflows.board import boards

    reg = boards.registration(
        name=name, kind=None if kind is None else kind.value, cols=cols, rows=rows, square_mm=square_mm,
        tag_cols=tag_cols,
        tag_rows=tag_rows, tag_size_mm=tag_size_mm, tag_spacing=tag_spacing, family=family,
        kalibr_target=from_kalibr, uncertainty_mm=uncertainty_mm,
        instrument=instrument, measured_by=measured_by, measured_on=measured_on, evidence=evidence,
        marker_mm=marker_mm, dictionary=dictionary, note=note, span_mm=span_mm,
        span_uncertainty_mm=span_uncertainty_mm, span_instrument=span_instrument, span_squares=span_squares,
        backing_mm=_pair_mm(backing_mm, "--backing-mm"),
        pattern_offset_mm=_pair_mm(pattern_offset_mm, "--pattern-offset-mm"),
        inverted=inverted, legacy_pattern=legacy,
    )  # fmt: skip
    board = boards.add_board(state(ctx).settings(), reg)
    if board.measurement.status == "nominal":
        stderr.print(
            f"warning: {board.ref} has a NOMINAL square size; every calibration made with it fails lint "
            "until the board is measured (board add again with the measurement)",
            soft_wrap=True,
            markup=False,
        )
    if (small := boards.square_size_warning(board)) is not None:
        stderr.print(f"warning: {small}", soft_wrap=True, markup=False)
    if wants_json(ctx, json_output):
        emit_json(board)
        return
    size = "tag" if board.kind == "aprilgrid" else "square"
    say(f"registered board {board.ref}: {pattern_text(board)}, {size} {square_text(board)}")


@board_app.command("list")
def list_(ctx: typer.Context, json_output: JsonFlag = False) -> None:
    """Every revision of every registered board."""
    from calibctl.workflows.board import boards

    all_boards = boards.list_boards(state(ctx).settings())
    if wants_json(ctx, json_output):
        emit_json([b.model_dump(mode="json") for b in all_boards])
        return
    if not all_boards:
        say("no boards registered yet; add one with `calibctl board add`")
        return
    table = Table("board", "pattern", "square size", "measured", "registered")
    for b in all_boards:
        m = b.measurement
        measured = f"{m.measured_on} by {m.measured_by}" if m.status != "nominal" else "-"
        table.add_row(
            shown(b.ref),
            shown(pattern_text(b)),
            shown(square_text(b)),
            shown(measured),
            b.created_at.date().isoformat(),
        )
    stdout.print(table)


@board_app.command("show")
def show(
    ctx: typer.Context,
    ref: Annotated[
        str, typer.Argument(metavar="NAME[@REV]", help="Board name, optionally @revision (default: latest).")
    ],
    json_output: JsonFlag = False,
) -> None:
    """One board revision with its measurement provenance."""
    from calibctl.workflows.board import boards

    board, revisions = boards.show_board(state(ctx).settings(), ref)
    if wants_json(ctx, json_output):
        emit_json(board)
        return
    print_board(board, revisions)


def register(app: typer.Typer) -> None:
    """Add the ``board`` command group to the root app."""
    app.add_typer(board_app, name="board")
