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
from typing import TYPE_CHECKING

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
    """What ``calibctl board add`` was given (lengths in millimetres, as printed on a caliper)."""

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
            f"a measured square size needs {', '.join(_MEASUREMENT_FLAGS.values())}; missing: {', '.join(missing)}",
            "give all of them, or only --square-mm to register the size as nominal (unmeasured)",
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
    squares = reg.span_squares if reg.span_squares is not None else max(reg.cols, reg.rows) - 1
    if not 0 < squares < max(reg.cols, reg.rows):
        raise UsageError(
            f"--span-squares {squares} must be between 1 and {max(reg.cols, reg.rows) - 1} "
            f"(a {reg.cols}x{reg.rows} board)"
        )
    if not 0 < reg.span_uncertainty_mm < reg.span_mm:
        raise UsageError(
            f"--span-uncertainty-mm {reg.span_uncertainty_mm:g} must be positive and smaller than the span"
        )
    verdict = compare_span(
        reg.square_mm / 1000,
        reg.uncertainty_mm / 1000,
        squares,
        reg.span_mm / 1000,
        reg.span_uncertainty_mm / 1000,
    )
    said = (
        f"--square-mm {reg.square_mm:g} x {squares} squares = {verdict.implied_m * 1000:.2f} mm, but --span-mm "
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
            f"{said}: they differ by {verdict.difference_m * 1000:+.2f} mm, more than {K_SIGMA:g} combined sigma "
            f"({verdict.combined_sigma_m * 1000:.2f} mm); the square size or the span is wrong",
            f"re-measure; the span implies {reg.span_mm / squares:.3f} mm squares. A wrong square size scales "
            "every distance the robot reports and leaves no residual",
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
    from calibctl.core.board.board_spec import BOARD_KINDS, BoardSpec  # numpy: not for `board list` / `show`

    now = now or utc_now()
    if not re.fullmatch(BOARD_NAME_PATTERN, reg.name):
        raise UsageError(
            f"'{reg.name}' is not a board name: use letters, digits, '.', '_' and '-' (at most 64, "
            "starting with a letter or digit)"
        )
    if reg.kind not in BOARD_KINDS:
        raise UsageError(f"unknown board kind '{reg.kind}'; choose {' or '.join(BOARD_KINDS)}")
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
        BoardSpec(
            reg.kind, reg.cols, reg.rows, reg.square_mm / 1000.0, marker_m, reg.dictionary,
            reg.legacy_pattern, reg.inverted,
        )  # fmt: skip
    except ValueError as exc:
        raise UsageError(f"board {reg.name}: {exc}") from exc
    measurement = _measurement(reg, now.date())
    backing = _backing(reg)
    try:
        return BoardRevision(
            name=reg.name,
            revision=1,
            kind=reg.kind,
            cols=reg.cols,
            rows=reg.rows,
            marker_size_m=marker_m,
            dictionary=reg.dictionary,
            inverted=reg.inverted,
            legacy_pattern=reg.legacy_pattern,
            measurement=measurement,
            created_at=now,
            created_by=created_by,
            note=reg.note,
            backing=backing,
        )
    except ValidationError as exc:
        raise UsageError(validation_message(exc, f"board {reg.name}")) from exc


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
        f"{board.ref} has a {square_mm:g} mm square: --square-mm takes millimetres. If {square_mm:g} was metres, "
        f"register it again with --square-mm {square_mm * 1000:g}; a wrong square size scales every distance "
        "and rig baseline and leaves no residual"
    )


def add_board(settings: Settings, reg: BoardRegistration) -> BoardRevision:
    """Register ``reg`` as the next revision of its name; returns what was stored (with its revision)."""
    from calibctl.store.repository import Store  # sqlalchemy: `board list` of SQLite reads through sqlite3

    board = build_board(reg, created_by=settings.operator)
    with Store.open(settings.db_url, signer=keys.signer_of(settings)) as store:
        if store.board_revisions(board.name):
            previous = store.get_board(board.name, None)
            check_reregistration(previous, board, board_failures(store, previous.ref))
        return store.add_board(board)


def list_boards(settings: Settings) -> list[BoardRevision]:
    def full_store() -> Store:
        from calibctl.store.repository import Store

        return Store.open(settings.db_url, create=False)

    return sqlite_reads.read(settings.db_url, lambda store: store.list_boards(), full_store)


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

    with Store.open(settings.db_url, create=False) as store:
        return store.get_board(name, revision), store.board_revisions(name)


def board_spec(board: BoardRevision) -> BoardSpec:
    """The core view of a registered board revision (what detection, the solve and the report use)."""
    from calibctl.core.board.board_spec import BoardSpec  # numpy: not for `board list` / `show`

    m = board.measurement
    if board.kind == "charuco":
        return BoardSpec(
            "charuco", board.cols, board.rows, m.square_size_m, board.marker_size_m, board.dictionary,
            board.legacy_pattern, board.inverted,
        )  # fmt: skip
    return BoardSpec.chessboard(board.cols, board.rows, m.square_size_m)
