"""Failed metric gauges in the store, by board revision (seed chapter 0).

A metric gauge that failed is already a signed, chained record: the capture session that carries it
(``CaptureSession.metric_gauge``, judged at capture) or the check event (``CheckEvent.distance``, judged by
``calibctl check --reference-distance`` on a stored calibration). This reads them back by the board revision
they were measured with, so every later use of that revision can be refused until it is re-registered (a new
revision) or overridden with a reason. No table of its own: the sessions and checks are the facts.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.orm import Session

from calibctl.store import codec
from calibctl.store.models import ArtifactRow, CheckEventRow, SessionRow
from calibctl.store.runner import Runner


@dataclass(frozen=True)
class GaugeFailure:
    """One failed gauge: where it was measured and what it read."""

    board_ref: str  # NAME@REV
    serial: str  # the camera it was measured through
    record: str  # "session ID" or "check ID of SERIAL@N"
    ratio: float  # recovered / surveyed distance
    recovered_m: float
    reference_m: float


class GaugeFailureStore:
    """The Store's failed gauges, read from the sessions and checks that carry them."""

    def __init__(self, runner: Runner) -> None:
        self._runner = runner

    def failed_gauges(self, board_refs: Iterable[str]) -> dict[str, list[GaugeFailure]]:
        """The failed gauges of each board revision in ``board_refs`` (NAME@REV), oldest first; a revision
        with none is left out. Every record is decoded (its hash re-checked) as any read does."""
        refs = sorted(set(board_refs))

        def work(s: Session) -> dict[str, list[GaugeFailure]]:
            out: dict[str, list[GaugeFailure]] = {}
            sessions = s.scalars(
                select(SessionRow)
                .where(SessionRow.board_ref.in_(refs), SessionRow.payload.like('%"metric_gauge"%'))
                .order_by(SessionRow.started_at)
            )
            for row in sessions:
                gauge = codec.decode_session(row).metric_gauge
                if gauge is not None and not gauge.distance.passed:
                    d = gauge.distance
                    out.setdefault(row.board_ref, []).append(
                        GaugeFailure(
                            row.board_ref,
                            row.serial,
                            f"session {row.session_id}",
                            d.ratio,
                            d.recovered_m,
                            d.reference_m,
                        )
                    )
            checks = s.execute(
                select(CheckEventRow, ArtifactRow.board_ref)
                .join(
                    ArtifactRow,
                    (ArtifactRow.serial == CheckEventRow.serial)
                    & (ArtifactRow.version == CheckEventRow.version),
                )
                .where(
                    ArtifactRow.board_ref.in_(refs),
                    CheckEventRow.passed.is_(False),
                    CheckEventRow.payload.like('%"distance"%'),
                )
                .order_by(CheckEventRow.id)
            )
            for check_row, board_ref in checks:
                event = codec.decode_check(check_row)
                checked = event.distance
                if checked is not None and not checked.passed:
                    out.setdefault(board_ref, []).append(
                        GaugeFailure(
                            board_ref,
                            event.serial,
                            f"check {event.check_id} of {event.serial}@{event.version}",
                            checked.ratio,
                            checked.recovered_m,
                            checked.reference_m,
                        )
                    )
            return out

        return self._runner.run(work) if refs else {}
