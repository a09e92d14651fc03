"""A failed metric gauge binds its board revision (seed chapter 0).

A 23 mm board registered for a 25 mm one leaves every residual as it was: only the gauge sees it, once. Its
verdict is therefore a fact of the board revision it was measured with (the session or check that failed,
``Store.failed_gauges``), not of the one session: every later calibration, solve, rig or hand-eye on that
revision is refused (or stored rejected, never active) until the board is re-registered with a measured span
(a new revision, ``calibctl board add``) or the failure is overridden with a recorded reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from calibctl.artifacts.board import parse_board_ref
from calibctl.errors import UsageError

if TYPE_CHECKING:
    from calibctl.artifacts.board import BoardRevision
    from calibctl.store.gauge_failures import GaugeFailure
    from calibctl.store.repository import Store


def failure_text(board_ref: str, failures: Sequence[GaugeFailure]) -> str:
    """One line naming the board revision and what its gauge read, e.g. for a lint finding or a refusal."""
    first = failures[0]
    more = f" (and {len(failures) - 1} more failed gauge(s))" if len(failures) > 1 else ""
    return (
        f"board {board_ref} failed its metric gauge: {first.record} on {first.serial} put the fixture board "
        f"{first.recovered_m:.4f} m away, {first.ratio:.3f}x the surveyed {first.reference_m:.4f} m{more}; "
        "every metric output made with this board revision is scaled by it and no residual shows it"
    )


def failure_fix(board_ref: str, flag: str = "--override-gauge REASON") -> str:
    """How to clear it: a new, measured revision, or an override with its reason."""
    name, _ = parse_board_ref(board_ref)
    return (
        f"re-register the board with a measured span (`calibctl board add {name} --square-mm ... "
        "--uncertainty-mm ... --span-mm ... --span-uncertainty-mm ... --span-instrument ...`: a new "
        f"revision) and capture again; if the gauge, not the board, was wrong: {flag} (recorded)"
    )


def board_failures(store: Store, board_ref: str) -> list[GaugeFailure]:
    """The failed gauges of one board revision (NAME@REV), oldest first."""
    return store.failed_gauges([board_ref]).get(board_ref, [])


def check_override(reason: str | None, board_ref: str, failures: Sequence[GaugeFailure], what: str) -> None:
    """An override needs a failed gauge to override (UsageError, exit 2, naming what has none)."""
    if reason is not None and not failures:
        raise UsageError(
            f"--override-gauge: {what} has no failed metric gauge (board {board_ref} has none); "
            "there is nothing to override",
            "leave --override-gauge out",
        )


def check_reregistration(
    previous: BoardRevision, board: BoardRevision, failures: Sequence[GaugeFailure]
) -> None:
    """A new revision of a board whose latest revision failed its gauge must clear it: a measured span (the
    square size checked against a long length) and a square size that is not the one the gauge failed;
    anything else is a UsageError (exit 2), nothing stored."""
    if not failures:
        return
    failed = failure_text(previous.ref, failures)
    old_mm, new_mm = previous.measurement.square_size_m * 1e3, board.measurement.square_size_m * 1e3
    if board.measurement.span is None:
        raise UsageError(
            f"{failed}; a new revision without a measured span cannot clear it",
            f"measure a long span too (--span-mm, --span-uncertainty-mm, --span-instrument): "
            f"{failure_fix(previous.ref)}",
        )
    if abs(new_mm - old_mm) <= 1e-9 * old_mm:
        raise UsageError(
            f"{failed}; the new revision says {new_mm:g} mm squares again: a re-registration that changes "
            "nothing clears nothing",
            "if the span confirms the squares, the gauge (fixture, surveyed distance) is what is wrong: "
            "check it and gauge again, or override the failure with --override-gauge REASON (recorded)",
        )
