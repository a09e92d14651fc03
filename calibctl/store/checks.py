"""Check events in the store (``calibctl check``): one immutable row per re-test of a calibration.

The row keeps the canonical JSON of the ``CheckEvent`` and its sha256 (re-checked on every read) plus
copies of the fields history filters on. UPDATE and DELETE are refused by revision 0006's triggers.
The table is declared here, beside the only code that uses it, on the models' ``Base``.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from typing import Any

from sqlalchemy import Boolean, ForeignKeyConstraint, Index, Integer, String, Text, select
from sqlalchemy.orm import Mapped, Session, mapped_column

from calibctl.artifacts.check import CheckEvent
from calibctl.artifacts.common import sha256_hex
from calibctl.errors import AlreadyExistsError
from calibctl.store import codec
from calibctl.store.history import statuses
from calibctl.store.models import SERIAL_LEN, SHA256_LEN, Base, UtcDateTime

CHECK_EVENTS_MESSAGE = "check events are append-only"


class CheckEventRow(Base):
    """One re-test of one calibration version (revision 0006)."""

    __tablename__ = "check_events"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    check_id: Mapped[str] = mapped_column(String(12), unique=True)
    serial: Mapped[str] = mapped_column(String(SERIAL_LEN))
    version: Mapped[int] = mapped_column(Integer)
    passed: Mapped[bool] = mapped_column(Boolean)
    at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (
        ForeignKeyConstraint(["serial", "version"], ["calibration_artifacts.serial", "calibration_artifacts.version"]),
        Index(None, "serial", "id"),
    )


_decode = codec.decode_check  # in codec, which the sqlite3 read path shares


class CheckStoreMixin:
    """Check-event methods of ``Store`` (which provides ``_run``)."""

    _run: Callable[..., Any]

    def add_check(self, event: CheckEvent) -> CheckEvent:
        """Append a check event; its calibration version must exist (NotFoundError naming the serials)."""
        payload = codec.canonical_text(event)

        def work(s: Session) -> CheckEvent:
            statuses(s, event.serial)  # an unknown serial is a NotFoundError, not a foreign-key error
            if s.scalar(select(CheckEventRow.id).where(CheckEventRow.check_id == event.check_id)) is not None:
                raise AlreadyExistsError(f"check {event.check_id} is already stored")
            s.add(CheckEventRow(check_id=event.check_id, serial=event.serial, version=event.version,
                                passed=event.passed, at=event.at, payload=payload,
                                payload_sha256=sha256_hex(payload.encode("utf-8"))))
            s.flush()
            return event

        return self._run(work, write=True)

    def checks(self, serial: str) -> list[CheckEvent]:
        """Every check of ``serial``, oldest first."""

        def work(s: Session) -> list[CheckEvent]:
            rows = s.scalars(select(CheckEventRow).where(CheckEventRow.serial == serial).order_by(CheckEventRow.id))
            return [_decode(r) for r in rows]

        return self._run(work)
