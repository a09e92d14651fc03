"""Board registry use cases: register a (re-)measured board, list boards, show one revision.

The square size is the one metric input of a calibration, so ``board add`` records it as a
measurement -- value, one-sigma uncertainty, instrument, who, when and the sha256 of an evidence
file -- or, when only ``--square-mm`` is given, as *nominal* (every calibration made with a nominal
board fails lint until the board is measured). Registering an existing name creates its next
revision; revisions never change.
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from calibctl import files
from calibctl.artifacts.board import (
    BOARD_NAME_PATTERN,
    BackingBoard,
    BoardRevision,
    SpanMeasurement,
    SquareMeasurement,
    parse_board_ref,
)
from calibctl.artifacts.common import sha256_hex, utc_now, validation_message
from calibctl.config import Settings
from calibctl.core.board.board_gauge import K_SIGMA, UNIT_SLIPS, compare_span
from calibctl.errors import InputError, UsageError
from calibctl.store import sqlite_reads
from calibctl.workflows.board.gauge_failures import board_failures, check_reregistration
from calibctl.workflows.store_admin import keys

if TYPE_CHECKING:
    from calibctl.core.board.board_spec import BoardSpec
    from calibctl.store.repository import Store

_MEASUREMENT_FLAGS = {
    "uncertainty_mm": "--uncertainty-mm",
    "instrument": "--instrument",
    "measured_by": "--measured-by",
    "measured_on": "--measured-on",
}
SMALLEST_LIKELY_SQUARE_MM = 1.0
"""Below this a square is more likely metres typed into --square-mm (0.025 for 25 mm) than a real target;
kept (microscope targets exist) but warned about, since a wrong square size leaves no residual."""
FUTURE_SLACK = dt.timedelta(days=1)
"""A measurement dated after tomorrow (UTC) is a typo, not a time zone."""


@dataclass(frozen=True)
class BoardRegistration:
    """What ``calibctl board add`` was given (lengths in millimetres, as printed on a caliper).

    An AprilGrid (``kind`` "aprilgrid") gives its tags per row and column as ``cols`` and ``rows``, the
    tag edge as ``square_mm`` (it is the measured length), ``tag_spacing`` and ``family`` (default 36h11).
    """

    name: str
    kind: str
    cols: int
    rows: int
    square_mm: float
    uncertainty_mm: float | None = None
    instrument: str | None = None
    measured_by: str | None = None
    measured_on: str | None = None
    evidence: Path | None = None
    marker_mm: float | None = None
    dictionary: str | None = None
    note: str | None = None
    span_mm: float | None = None
    span_uncertainty_mm: float | None = None
    span_instrument: str | None = None
    span_squares: int | None = None
    backing_mm: tuple[float, float] | None = None
    pattern_offset_mm: tuple[float, float] | None = None
    inverted: bool = False
    legacy_pattern: bool = False
    tag_spacing: float | None = None
    family: str | None = None


def registration(
    *,
    kind: str | None,
    cols: int | None,
    rows: int | None,
    square_mm: float | None,
    tag_cols: int | None = None,
    tag_rows: int | None = None,
    tag_size_mm: float | None = None,
    tag_spacing: float | None = None,
    kalibr_target: Path | None = None,
    **rest: Any,
) -> BoardRegistration:
    """The registration ``board add``'s options describe: a chessboard or ChArUco board by ``--cols``,
    ``--rows`` and ``--square-mm``; an AprilGrid by ``--tag-cols``, ``--tag-rows``, ``--tag-size-mm`` and
    ``--tag-spacing`` or by Kalibr's target.yaml (``--from-kalibr``), never both. Without ``kind``: an
    AprilGrid when Kalibr's target.yaml is given (the file says so, as a Kalibr user brings it), else a
    chessboard."""
    kind = kind or ("aprilgrid" if kalibr_target is not None else "chessboard")
    grid = {"--cols": cols, "--rows": rows, "--square-mm": square_mm}
    tags = {"--tag-cols": tag_cols, "--tag-rows": tag_rows, "--tag-size-mm": tag_size_mm}
    tags["--tag-spacing"] = tag_spacing
    if kind != "aprilgrid":
        extra = [flag for flag, v in tags.items() if v is not None] + (
            ["--from-kalibr"] if kalibr_target else []
        )
        if extra:
            raise UsageError(f"{', '.join(extra)} describe an AprilGrid", "add --kind aprilgrid")
        missing = [flag for flag, v in grid.items() if v is None]
        if missing:
            raise UsageError(f"a {kind} needs {', '.join(missing)}", "e.g. --cols 9 --rows 6 --square-mm 25")
        assert cols is not None and rows is not None and square_mm is not None
        return BoardRegistration(rest.pop("name"), kind, cols, rows, square_mm, **rest)
    given = [flag for flag, v in grid.items() if v is not None]
    if given:
        raise UsageError(
            f"{', '.join(given)} describe a chessboard or ChArUco grid",
            "an AprilGrid takes --tag-cols, --tag-rows, --tag-size-mm and --tag-spacing (or --from-kalibr)",
        )
    if kalibr_target is not None:
        both = [flag for flag, v in tags.items() if v is not None]
        if both:
            raise UsageError(
                f"--from-kalibr gives the grid; {', '.join(both)} would contradict it",
                "give either Kalibr's target.yaml or the --tag-* options",
            )
        target = read_kalibr_target(kalibr_target)
        tag_cols, tag_rows, tag_size_mm = target.tag_cols, target.tag_rows, target.tag_size_mm
        tag_spacing = target.tag_spacing
    tags = {"--tag-cols": tag_cols, "--tag-rows": tag_rows, "--tag-size-mm": tag_size_mm}
    tags["--tag-spacing"] = tag_spacing
    missing = [flag for flag, v in tags.items() if v is None]
    if missing:
        raise UsageError(
            f"an AprilGrid needs {', '.join(missing)}",
            "e.g. --tag-cols 6 --tag-rows 6 --tag-size-mm 88 --tag-spacing 0.3, or --from-kalibr target.yaml",
        )
    assert tag_cols is not None and tag_rows is not None and tag_size_mm is not None
    return BoardRegistration(
        rest.pop("name"), kind, tag_cols, tag_rows, tag_size_mm, tag_spacing=tag_spacing, **rest
    )


def parse_measured_on(text: str, today: dt.date) -> dt.date:
    """``YYYY-MM-DD`` -> date; refuses other spellings and dates in the future."""
    if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", text.strip()):
        raise UsageError(f"--measured-on '{text}' is not a date; use YYYY-MM-DD (e.g. 2026-03-11)")
    try:
        day = dt.date.fromisoformat(text.strip())
    except ValueError as exc:
        raise UsageError(f"--measured-on '{text}' is not a date: {exc}") from exc
    if day > today + FUTURE_SLACK:
        raise UsageError(
            f"--measured-on {day} is in the future (today is {today})", "give the day it was measured"
        )
    return day


def read_evidence(path: Path) -> tuple[str, str]:
    """(sha256, file name) of an evidence file (a photo of the calipers on the board, a lab report)."""
    try:
        with files.open_regular(path, "read the evidence file") as handle:  # a FIFO is refused, not waited on
            data = handle.read()
    except OSError as exc:
        raise InputError(f"cannot read evidence file {path}: {exc.strerror or exc}") from exc
    if not data:
        raise InputError(f"evidence file {path} is empty")
    return sha256_hex(data), path.name


def _size_flag(reg: BoardRegistration) -> str:
    return "--tag-size-mm" if reg.kind == "aprilgrid" else "--square-mm"


def _measurement(reg: BoardRegistration, today: dt.date) -> SquareMeasurement:
    square_m = reg.square_mm / 1000.0
    given = {flag for field, flag in _MEASUREMENT_FLAGS.items() if getattr(reg, field) is not None}
    if not given and reg.evidence is None:
        if reg.span_mm is not None:
            raise UsageError(
                "--span-mm checks a measured square size; this one is nominal",
                "give the square's measurement too (--uncertainty-mm, --instrument, --measured-by, "
                "--measured-on)",
            )
        return SquareMeasurement(status="nominal", square_size_m=square_m)
    missing = [flag for flag in _MEASUREMENT_FLAGS.values() if flag not in given]
    if missing:
        raise UsageError(
            f"a measured square size needs {', '.join(_MEASUREMENT_FLAGS.values())}; missing: "
            f"{', '.join(missing)}",
            f"give all of them, or only {_size_flag(reg)} to register the size as nominal (unmeasured)",
        )
    assert reg.uncertainty_mm is not None and reg.measured_on is not None
    if not 0 < reg.uncertainty_mm < reg.square_mm:
        raise UsageError(
            f"--uncertainty-mm {reg.uncertainty_mm:g} must be positive and smaller than the square"
        )
    evidence_sha, evidence_name = read_evidence(reg.evidence) if reg.evidence is not None else (None, None)
    day = parse_measured_on(reg.measured_on, today)
    span = _span(reg, day)
    return SquareMeasurement(
        status="measured" if span is not None else "measured-single",
        span=span,
        square_size_m=square_m,
        uncertainty_m=reg.uncertainty_mm / 1000.0,
        instrument=reg.instrument,
        measured_by=reg.measured_by,
        measured_on=day,
        evidence_sha256=evidence_sha,
        evidence_name=evidence_name,
    )


_SPAN_FLAGS = {"span_uncertainty_mm": "--span-uncertainty-mm", "span_instrument": "--span-instrument"}


def _span(reg: BoardRegistration, day: dt.date) -> SpanMeasurement | None:
    """The span measurement, refused when the square size disagrees with it (seed chapter 0's typo)."""
    if reg.span_mm is None:
        extra = [
            flag
            for name, flag in {**_SPAN_FLAGS, "span_squares": "--span-squares"}.items()
            if getattr(reg, name) is not None
        ]
        if extra:
            raise UsageError(f"{', '.join(extra)} describe a span measurement: give --span-mm too")
        return None
    missing = [flag for name, flag in _SPAN_FLAGS.items() if getattr(reg, name) is None]
    if missing:
        raise UsageError(
            f"a span measurement needs {', '.join(missing)}",
            "the span's own instrument and one-sigma, e.g. --span-uncertainty-mm 0.1 --span-instrument "
            "'steel rule'",
        )
    assert (
        reg.span_uncertainty_mm is not None
        and reg.span_instrument is not None
        and reg.uncertainty_mm is not None
    )
    aprilgrid = reg.kind == "aprilgrid"
    most = max(reg.cols, reg.rows) if aprilgrid else max(reg.cols, reg.rows) - 1
    squares = reg.span_squares if reg.span_squares is not None else most
    if not 0 < squares <= most:
        raise UsageError(
            f"--span-squares {squares} must be between 1 and {most} "
            f"(a {reg.cols}x{reg.rows}{'-tag' if aprilgrid else ''} board)"
        )
    # An AprilGrid's span runs from a tag's outer corner over ``squares`` tags and the gaps between them.
    edges = squares + (squares - 1) * (reg.tag_spacing or 0.0) if aprilgrid else float(squares)
    size_flag = _size_flag(reg)
    if not 0 < reg.span_uncertainty_mm < reg.span_mm:
        raise UsageError(
            f"--span-uncertainty-mm {reg.span_uncertainty_mm:g} must be positive and smaller than the span"
        )
    verdict = compare_span(
        reg.square_mm / 1000,
        reg.uncertainty_mm / 1000,
        edges,
        reg.span_mm / 1000,
        reg.span_uncertainty_mm / 1000,
    )
    count = f"{edges:g} (tags and gaps)" if aprilgrid else f"{squares} squares"
    said = (
        f"{size_flag} {reg.square_mm:g} x {count} = "
        f"{verdict.implied_m * 1000:.2f} mm, but --span-mm "
        f"{reg.span_mm:g}"
    )
    if verdict.unit_factor is not None:
        slip = verdict.unit_factor if verdict.unit_factor >= 1 else 1 / verdict.unit_factor
        raise UsageError(
            f"{said} is {verdict.unit_factor:g}x that: wrong units ({UNIT_SLIPS[slip]}?), not a measurement",
            "give both lengths in millimetres",
        )
    if not verdict.consistent:
        raise UsageError(
            f"{said}: they differ by {verdict.difference_m * 1000:+.2f} mm, more than {K_SIGMA:g} combined "
            "sigma "
            f"({verdict.combined_sigma_m * 1000:.2f} mm); the square size or the span is wrong",
            f"re-measure; the span implies {reg.span_mm / edges:.3f} mm {'tags' if aprilgrid else 'squares'}"
            ". "
            "A wrong square size scales every distance the robot reports and leaves no residual",
        )
    return SpanMeasurement(
        span_m=reg.span_mm / 1000.0,
        squares=squares,
        uncertainty_m=reg.span_uncertainty_mm / 1000.0,
        instrument=reg.span_instrument,
        measured_by=reg.measured_by or "",
        measured_on=day,
    )


def build_board(reg: BoardRegistration, *, created_by: str, now: dt.datetime | None = None) -> BoardRevision:
    """The BoardRevision a registration describes (revision 1 here; the store allocates the real one)."""
    from calibctl.core.board.board_spec import BOARD_KINDS  # numpy: not for `board list` / `show`

    now = now or utc_now()
    if not re.fullmatch(BOARD_NAME_PATTERN, reg.name):
        raise UsageError(
            f"'{reg.name}' is not a board name: use letters, digits, '.', '_' and '-' (at most 64, "
            "starting with a letter or digit)"
        )
    if reg.kind not in BOARD_KINDS:
        raise UsageError(f"unknown board kind '{reg.kind}'; choose {', '.join(BOARD_KINDS)}")
    spec = _aprilgrid_spec(reg) if reg.kind == "aprilgrid" else _grid_spec(reg)
    measurement = _measurement(reg, now.date())
    backing = _backing(reg)
    try:
        return BoardRevision(
            name=reg.name,
            revision=1,
            kind=reg.kind,
            cols=spec.cols,
            rows=spec.rows,
            marker_size_m=spec.marker_size_m,
            dictionary=spec.dictionary,
            inverted=reg.inverted,
            legacy_pattern=reg.legacy_pattern,
            tag_spacing=spec.tag_spacing,
            measurement=measurement,
            created_at=now,
            created_by=created_by,
            note=reg.note,
            backing=backing,
        )
    except ValidationError as exc:
        raise UsageError(validation_message(exc, f"board {reg.name}")) from exc


def _aprilgrid_spec(reg: BoardRegistration) -> BoardSpec:
    """The AprilGrid a registration describes; what does not apply to one is refused, naming the fix."""
    from calibctl.core.board.board_spec import APRILTAG_FAMILIES, BoardSpec

    given = [
        flag
        for flag, value in (
            ("--marker-mm", reg.marker_mm),
            ("--dictionary", reg.dictionary),
            ("--inverted", reg.inverted or None),
            ("--legacy", reg.legacy_pattern or None),
            ("--backing-mm", reg.backing_mm),
        )
        if value is not None
    ]
    if given:
        raise UsageError(
            f"{', '.join(given)} do not apply to an AprilGrid",
            "give --tag-cols, --tag-rows, --tag-size-mm, --tag-spacing and optionally --family (36h11)",
        )
    if not 0 < reg.square_mm < 1000:
        raise UsageError(f"--tag-size-mm {reg.square_mm:g} must be a positive length below 1000 mm")
    if reg.tag_spacing is None:
        raise UsageError(
            "an AprilGrid needs --tag-spacing", "the gap between tags over the tag edge, e.g. 0.3"
        )
    if not (1 <= reg.cols <= 100 and 1 <= reg.rows <= 100):
        raise UsageError(f"--tag-cols {reg.cols} and --tag-rows {reg.rows} must be 1 to 100 tags")
    family = reg.family or "36h11"
    try:
        return BoardSpec.aprilgrid(reg.cols, reg.rows, reg.square_mm / 1000.0, reg.tag_spacing, family)
    except ValueError as exc:
        raise UsageError(
            f"board {reg.name}: {exc}",
            f"--tag-spacing is the gap over the tag edge, in (0, 1]; --family one of "
            f"{', '.join(APRILTAG_FAMILIES)} (a family OpenCV lacks cannot be detected: print a 36h11 grid)",
        ) from exc


KALIBR_TARGET_FIELDS = ("tagCols", "tagRows", "tagSize", "tagSpacing")


@dataclass(frozen=True)
class KalibrAprilgrid:
    """Kalibr's target.yaml of an AprilGrid: tags per row and column, tag edge (mm), spacing ratio."""

    tag_cols: int
    tag_rows: int
    tag_size_mm: float
    tag_spacing: float


def read_kalibr_target(path: Path) -> KalibrAprilgrid:
    """Kalibr's ``target.yaml`` (``target_type: 'aprilgrid'``, ``tagCols``, ``tagRows``, ``tagSize`` in
    metres, ``tagSpacing`` as a ratio), read bounded; any other target, or a field missing or out of
    range, is an InputError naming the file and the fix."""
    from calibctl import bounded

    data = bounded.load_file(path, "read the Kalibr target file")
    if not isinstance(data, dict):
        raise InputError(f"{path} is not a Kalibr target.yaml (a mapping of target_type, tagCols, ...)")
    kind = data.get("target_type")
    if kind != "aprilgrid":
        raise InputError(
            f"{path} describes a Kalibr target_type {kind!r}, not an aprilgrid",
            "register a checkerboard with --kind chessboard --cols --rows --square-mm (Kalibr's targetCols, "
            "targetRows, rowSpacingMeters x 1000), or give the aprilgrid's target.yaml",
        )
    missing = [name for name in KALIBR_TARGET_FIELDS if name not in data]
    if missing:
        raise InputError(f"{path}: an aprilgrid target.yaml needs {', '.join(missing)}", "see Kalibr's wiki")
    values = {name: data[name] for name in KALIBR_TARGET_FIELDS}
    if any(isinstance(v, bool) or not isinstance(v, int | float) for v in values.values()):
        raise InputError(f"{path}: {', '.join(KALIBR_TARGET_FIELDS)} must be numbers, got {values}")
    cols, rows, size_m, spacing = (values[name] for name in KALIBR_TARGET_FIELDS)
    if cols != int(cols) or rows != int(rows) or not (1 <= cols <= 100 and 1 <= rows <= 100):
        raise InputError(f"{path}: tagCols {cols} and tagRows {rows} must be whole numbers of tags, 1 to 100")
    if not 0 < size_m < 1.0:
        raise InputError(
            f"{path}: tagSize {size_m:g} is not a tag edge in metres (0 to 1 m)",
            "Kalibr's tagSize is in metres: 0.088 for 88 mm tags",
        )
    if not 0 < spacing <= 1:
        raise InputError(
            f"{path}: tagSpacing {spacing:g} is not a ratio in (0, 1]",
            "Kalibr's tagSpacing is the gap over the tag edge: 0.3 for a 26.4 mm gap between 88 mm tags",
        )
    return KalibrAprilgrid(int(cols), int(rows), float(size_m) * 1000.0, float(spacing))


def _grid_spec(reg: BoardRegistration) -> BoardSpec:
    """The chessboard or ChArUco board a registration describes."""
    from calibctl.core.board.board_spec import BoardSpec

    if reg.tag_spacing is not None or reg.family is not None:
        raise UsageError("--tag-spacing and --family apply to AprilGrids only", "add --kind aprilgrid")
    if not 0 < reg.square_mm < 1000:
        raise UsageError(f"--square-mm {reg.square_mm:g} must be a positive length below 1000 mm")
    if reg.kind == "chessboard" and (reg.marker_mm is not None or reg.dictionary is not None):
        raise UsageError("--marker-mm and --dictionary apply to ChArUco boards only", "add --kind charuco")
    if reg.kind == "chessboard" and (reg.inverted or reg.legacy_pattern):
        raise UsageError("--inverted and --legacy apply to ChArUco boards only", "add --kind charuco")
    if reg.kind == "charuco" and (reg.marker_mm is None or reg.dictionary is None):
        raise UsageError("a ChArUco board needs --marker-mm and --dictionary (e.g. DICT_5X5_100)")
    marker_m = reg.marker_mm / 1000.0 if reg.marker_mm is not None else None
    try:  # the geometry the detector will use: checks the grid, the marker and the dictionary name
        return BoardSpec(
            reg.kind, reg.cols, reg.rows, reg.square_mm / 1000.0, marker_m, reg.dictionary,
            reg.legacy_pattern, reg.inverted,
        )  # fmt: skip
    except ValueError as exc:
        raise UsageError(f"board {reg.name}: {exc}") from exc


def _backing(reg: BoardRegistration) -> BackingBoard | None:
    """The backing board of ``--backing-mm W,H`` / ``--pattern-offset-mm X,Y``, or None."""
    if reg.backing_mm is None:
        if reg.pattern_offset_mm is not None:
            raise UsageError("--pattern-offset-mm needs --backing-mm W,H (the board it is offset on)")
        return None
    w, h = reg.backing_mm
    if not (0 < w < 10000 and 0 < h < 10000):
        raise UsageError(f"--backing-mm {w:g},{h:g} must be two positive lengths below 10000 mm")
    ox, oy = reg.pattern_offset_mm or (0.0, 0.0)
    pattern = ((reg.cols + 1) * reg.square_mm, (reg.rows + 1) * reg.square_mm)
    if pattern[0] + 2 * abs(ox) > w or pattern[1] + 2 * abs(oy) > h:
        raise UsageError(
            f"a {reg.cols + 1} x {reg.rows + 1}-square pattern ({pattern[0]:g} x {pattern[1]:g} mm, "
            f"offset {ox:g},{oy:g} mm) does not fit on a {w:g} x {h:g} mm backing board",
            "--backing-mm is W along the rows of --cols corners, H along the --rows direction",
        )
    return BackingBoard(width_m=w / 1000.0, height_m=h / 1000.0, pattern_offset_m=(ox / 1000.0, oy / 1000.0))


def square_size_warning(board: BoardRevision) -> str | None:
    """A warning when the square is so small that it was probably given in metres, not millimetres."""
    square_mm = board.measurement.square_size_m * 1000.0
    if square_mm >= SMALLEST_LIKELY_SQUARE_MM:
        return None
    return (
        f"{board.ref} has a {square_mm:g} mm square: --square-mm takes millimetres. If {square_mm:g} was "
        "metres, "
        f"register it again with --square-mm {square_mm * 1000:g}; a wrong square size scales every distance "
        "and rig baseline and leaves no residual"
    )


def add_board(settings: Settings, reg: BoardRegistration) -> BoardRevision:
    """Register ``reg`` as the next revision of its name; returns what was stored (with its revision)."""
    from calibctl.store.repository import Store  # sqlalchemy: `board list` of SQLite reads through sqlite3

    board = build_board(reg, created_by=settings.operator)
    with Store.open(
        settings.db_url, signer=keys.signer_of(settings), trusted=keys.read_trust(settings)
    ) as store:
        if store.board_revisions(board.name):
            previous = store.get_board(board.name, None)
            check_reregistration(previous, board, board_failures(store, previous.ref))
        return store.add_board(board)


def list_boards(settings: Settings) -> list[BoardRevision]:
    def full_store() -> Store:
        from calibctl.store.repository import Store

        return Store.open(settings.db_url, create=False, trusted=trusted)

    trusted = keys.read_trust(settings)
    return sqlite_reads.read(settings.db_url, lambda store: store.list_boards(), full_store, trusted)


def board_ref(ref: str) -> tuple[str, int | None]:
    """``NAME`` or ``NAME@REV`` as given on a command line -> (name, revision or None for the latest); a
    malformed reference is a UsageError (exit 2) naming it."""
    try:
        return parse_board_ref(ref)
    except ValueError as exc:
        raise UsageError(str(exc)) from exc


def show_board(settings: Settings, ref: str) -> tuple[BoardRevision, list[int]]:
    """``NAME`` (latest) or ``NAME@REV`` -> that revision, and every revision number of the board."""
    name, revision = board_ref(ref)
    from calibctl.store.repository import Store

    with Store.open(settings.db_url, create=False, trusted=keys.read_trust(settings)) as store:
        return store.get_board(name, revision), store.board_revisions(name)


def board_spec(board: BoardRevision) -> BoardSpec:
    """The core view of a registered board revision (what detection, the solve and the report use)."""
    from calibctl.core.board.board_spec import BoardSpec  # numpy: not for `board list` / `show`

    m = board.measurement
    if board.kind == "aprilgrid":
        return BoardSpec(
            "aprilgrid", board.cols, board.rows, m.square_size_m, dictionary=board.dictionary,
            tag_spacing=board.tag_spacing,
        )  # fmt: skip
    if board.kind == "charuco":
        return BoardSpec(
            "charuco", board.cols, board.rows, m.square_size_m, board.marker_size_m, board.dictionary,
            board.legacy_pattern, board.inverted,
        )  # fmt: skip
    return BoardSpec.chessboard(board.cols, board.rows, m.square_size_m)
