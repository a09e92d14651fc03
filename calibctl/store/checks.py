"""Check events in the store (``calibctl check``): one immutable row per re-test of a calibration.

The row keeps the canonical JSON of the ``CheckEvent`` and its sha256 (re-checked on every read) plus
copies of the fields history filters on. UPDATE and DELETE are refused by revision 0006's triggers.
The table (``models.CheckEventRow``) is chained per serial (revision 0007, ``chain.STREAMS["check"]``).
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import select
from sqlalchemy.orm import Session

from calibctl.artifacts.check import CheckEvent
from calibctl.artifacts.common import sha256_hex
from calibctl.errors import AlreadyExistsError
from calibctl.store import chain, codec, counters
from calibctl.store.history import CAMERAS
from calibctl.store.models import CheckEventRow
from calibctl.store.runner import Runner

CHECK_EVENTS_MESSAGE = "check events are append-only"


class CheckStore:
    """The Store's check events."""

    def __init__(self, runner: Runner) -> None:
        self._runner = runner

    def add_check(self, event: CheckEvent) -> CheckEvent:
        """Append a check event; its calibration version must exist (NotFoundError naming the serials)."""
        payload = codec.canonical_text(event)

        def work(s: Session) -> CheckEvent:
            CAMERAS.statuses(s, event.serial)  # an unknown serial is a NotFoundError, not a foreign-key error
            if s.scalar(select(CheckEventRow.id).where(CheckEventRow.check_id == event.check_id)) is not None:
                raise AlreadyExistsError(f"check {event.check_id} is already stored")
            counters.next_value(s, "check", event.serial)  # the serial's check chain: its lock and its length
            row = CheckEventRow(
                check_id=event.check_id,
                serial=event.serial,
                version=event.version,
                passed=event.passed,
                at=event.at,
                payload=payload,
                payload_sha256=sha256_hex(payload.encode("utf-8")),
            )
            chain.link(s, chain.STREAMS["check"], row, self._runner.signer)
            s.add(row)
            s.flush()
            return event

        return self._runner.run(work, write=True)

    def checks(self, serial: str) -> list[CheckEvent]:
        """Every check of ``serial``, oldest first."""

        def work(s: Session) -> list[CheckEvent]:
            rows = s.scalars(
                select(CheckEventRow).where(CheckEventRow.serial == serial).order_by(CheckEventRow.id)
            )
            return [codec.decode_check(r) for r in rows]

        return self._runner.run(work)

    def checks_since(self, serials: list[str], since: datetime) -> list[tuple[CheckEvent, str]]:
        """Every check of ``serials`` stamped at or after ``since``, oldest first, each with its row's payload
        sha256 (what a rollout's promote records as the evidence its gate read)."""

        def work(s: Session) -> list[tuple[CheckEvent, str]]:
            rows = s.scalars(
                select(CheckEventRow)
                .where(CheckEventRow.serial.in_(serials), CheckEventRow.at >= since)
                .order_by(CheckEventRow.id)
            )
            return [(codec.decode_check(r), r.payload_sha256) for r in rows]

        return self._runner.run(work) if serials else []
