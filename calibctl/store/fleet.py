"""The fleet's log in the store (revision 0009_fleet_diff25): ``FleetEvent`` rows, one chained stream.

The row keeps the canonical JSON of the event and its sha256 (re-checked on every read) plus copies of
the fields queries filter on. UPDATE and DELETE are refused by the migration's triggers. What an event
refers to is checked in the same transaction as its insert: a robot is registered once; an assignment
names a registered robot, a serial it carries and a stored version of that serial.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex
from calibctl.artifacts.fleet import FleetEvent
from calibctl.errors import AlreadyExistsError, NotFoundError, UsageError
from calibctl.signing import Signer
from calibctl.store import chain, codec, counters
from calibctl.store.history import statuses
from calibctl.store.models import FleetEventRow


def decode_fleet_event(row: FleetEventRow) -> FleetEvent:
    what = f"fleet event {row.id} ({row.robot}, {row.kind})"
    return codec.decode_payload(FleetEvent, row.payload, row.payload_sha256, what,
                                {"robot": row.robot, "kind": row.kind})


def _registration(s: Session, robot: str) -> FleetEvent | None:
    row = s.scalars(select(FleetEventRow).where(FleetEventRow.robot == robot, FleetEventRow.kind == "register")
                    .order_by(FleetEventRow.id).limit(1)).first()
    return None if row is None else decode_fleet_event(row)


class FleetStoreMixin:
    """Fleet methods of ``Store`` (which provides ``_run``)."""

    _run: Callable[..., Any]
    signer: Signer | None

    def add_fleet_event(self, event: FleetEvent) -> int:
        """Append ``event`` to the fleet's log; its position (1, 2, ...). Refused, nothing written: a second
        registration of a robot (AlreadyExistsError); an assignment to an unknown robot, of a serial the robot
        does not carry (UsageError), or of an unknown serial or version (NotFoundError); a rejected version."""
        payload = codec.canonical_text(event)

        def work(s: Session) -> int:
            position = counters.next_value(s, "chain", "fleet")  # the stream's lock until commit
            registered = _registration(s, event.robot)
            if event.kind == "register":
                if registered is not None:
                    raise AlreadyExistsError(f"robot {event.robot} is already registered",
                                             "robots are registered once; `calibctl fleet status` lists them")
            else:
                _check_assignment(s, event, registered)
            row = FleetEventRow(id=position, robot=event.robot, kind=event.kind, at=event.at, payload=payload,
                                payload_sha256=sha256_hex(payload.encode("utf-8")))
            chain.link(s, chain.STREAMS["fleet"], row, self.signer)
            s.add(row)
            s.flush()
            return position

        return self._run(work, write=True)

    def fleet_events(self) -> list[FleetEvent]:
        """The whole fleet log, oldest first."""
        return self._run(lambda s: [decode_fleet_event(r) for r in s.scalars(select(FleetEventRow).order_by(FleetEventRow.id))])


def _check_assignment(s: Session, event: FleetEvent, registered: FleetEvent | None) -> None:
    if registered is None:
        raise NotFoundError(f"robot {event.robot} is not registered",
                            f"register it first: calibctl fleet add {event.robot} --serial SERIAL ...")
    assert event.serial is not None and event.version is not None  # the document's own validator
    if event.serial not in registered.serials:
        raise UsageError(f"robot {event.robot} does not carry {event.serial} (it carries "
                         f"{', '.join(registered.serials) or 'no camera serials'})",
                         "assign one of its own serials")
    known = statuses(s, event.serial)  # NotFoundError for an unknown serial
    status = known.get(event.version)
    if status is None:
        raise NotFoundError(f"{event.serial} has no version {event.version}; versions: "
                            f"{', '.join(str(v) for v in sorted(known))}", f"see `calibctl history {event.serial}`")
    if status != "accepted":
        raise UsageError(f"{event.serial}@{event.version} is {status}: a robot must not run it",
                         "assign an accepted version")
