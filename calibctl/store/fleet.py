"""The fleet's log in the store (revision 0010_fleet_diff25): ``FleetEvent`` rows, one chained stream.

The row keeps the canonical JSON of the event and its sha256 (re-checked on every read) plus copies of
the fields queries filter on. UPDATE and DELETE are refused by the migration's triggers. What an event
refers to is checked in the same transaction as its insert: a robot is registered once; an assignment
names a registered robot, a serial it carries and a stored version of that serial.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex
from calibctl.artifacts.fleet import FleetEvent
from calibctl.errors import AlreadyExistsError, NotFoundError, StaleActiveVersionError, UsageError
from calibctl.signing import Signer
from calibctl.store import chain, codec, counters, fleet_checkpoints
from calibctl.store.codec import decode_fleet_event
from calibctl.store.fleet_checkpoints import Loaded
from calibctl.store.history import CAMERAS
from calibctl.store.models import FleetEventRow
from calibctl.store.rigs import RIGS
from calibctl.store.runner import Runner


@dataclass(frozen=True)
class RigActivationStep:
    """A rig version a fleet step makes active in the same transaction (a promote, or a rollback restoring the
    version a promote replaced): compare-and-set on ``expected_active``, the active version the step decided
    on."""

    rig: str
    version: int
    kind: str  # "activate" (promote) or "rollback"
    expected_active: int | None
    reason: str


def _registration(s: Session, robot: str) -> FleetEvent | None:
    row = s.scalars(
        select(FleetEventRow)
        .where(FleetEventRow.subject == robot, FleetEventRow.kind == "register")
        .order_by(FleetEventRow.id)
        .limit(1)
    ).first()
    return None if row is None else decode_fleet_event(row, by_chain=True)


class FleetStore:
    """The Store's fleet log (and the rig activations a fleet step makes with it)."""

    def __init__(self, runner: Runner) -> None:
        self._runner = runner

    def add_fleet_event(self, event: FleetEvent) -> int:
        """Append ``event`` to the fleet's log; its position (1, 2, ...). Refused, nothing written: a second
        registration of a robot (AlreadyExistsError); an assignment to an unknown robot, of a serial the robot
        does not carry (UsageError), or of an unknown serial or version (NotFoundError); a rejected
        version."""
        return self.append_fleet_events([event])

    def append_fleet_events(
        self,
        events: Sequence[FleetEvent],
        after: int | None = None,
        rig_steps: Sequence[RigActivationStep] = (),
    ) -> int:
        """Append ``events`` in one transaction (all or none); the position of the last. With ``after`` (the
        log's length the caller decided on) it is a compare-and-set: a log that grew meanwhile refuses the
        whole batch (StaleActiveVersionError: read it again), so a promote or rollback never acts on a stale
        fleet. ``rig_steps`` are appended to the rigs' activation log in the same transaction (a rig whose
        active version moved since the caller read it refuses the whole batch)."""

        def work(s: Session) -> int:
            current = counters.peek(s, "chain", "fleet") or 0
            if after is not None and current != after:
                raise StaleActiveVersionError(
                    f"the fleet log changed underneath this step ({current - after} event(s) since it was "
                    "read); "
                    "nothing written",
                    "run the command again",
                )
            position = current
            for event in events:
                position = counters.next_value(s, "chain", "fleet")  # the stream's lock until commit
                _check(s, event)
                payload = codec.canonical_text(event)
                row = FleetEventRow(
                    id=position,
                    subject=event.subject,
                    kind=event.kind,
                    at=event.at,
                    payload=payload,
                    payload_sha256=sha256_hex(payload.encode("utf-8")),
                )
                chain.link(s, chain.STREAMS["fleet"], row, self._runner.signer)
                s.add(row)
                s.flush()
            for step in rig_steps:
                _activate_rig(s, step, events[-1], self._runner.signer)
            if position > current:
                fleet_checkpoints.write_if_due(s, position, self._runner.signer)
            return position

        return self._runner.run(work, write=True)

    def active_versions(self) -> tuple[dict[str, int], dict[str, int]]:
        """Every serial's and every rig's active version (its latest activation event's), two queries in all:
        ``fleet status`` reads them for the whole fleet at once, not one serial at a time."""

        def work(s: Session) -> tuple[dict[str, int], dict[str, int]]:
            out = []
            for history in (CAMERAS, RIGS):
                table, key = history.event_model, getattr(history.event_model, history.key)
                latest = select(func.max(table.id).label("id")).group_by(key).subquery()
                out.append(
                    {
                        str(name): int(v)
                        for name, v in s.execute(
                            select(key, table.version).join(latest, table.id == latest.c.id)
                        )
                    }
                )
            return out[0], out[1]

        return self._runner.run(work)

    def fleet(self) -> Loaded:
        """The fleet log replayed (settled): from the newest checkpoint that still matches the log, then the
        events after it (``fleet_checkpoints``); the same state a replay of the whole log gives."""

        def work(s: Session) -> Loaded:
            loaded = fleet_checkpoints.load(s, trusted=self._runner.trusted)
            loaded.fleet.settle()
            return loaded

        return self._runner.run(work)

    def fleet_events(self) -> list[FleetEvent]:
        """The whole fleet log, oldest first."""
        return self._runner.run(
            lambda s: [
                decode_fleet_event(r, by_chain=True)
                for r in s.scalars(select(FleetEventRow).order_by(FleetEventRow.id))
            ]
        )


def _check(s: Session, event: FleetEvent) -> None:
    """What the event refers to exists and may be used (see ``append_fleet_events``)."""
    if event.kind == "register":
        if _registration(s, event.subject) is not None:
            raise AlreadyExistsError(
                f"robot {event.robot} is already registered",
                "robots are registered once; `calibctl fleet status` lists them",
            )
    elif event.kind == "assign":
        _check_assignment(s, event, _registration(s, event.subject))
    elif event.kind == "rollout":
        if _rollout(s, event.subject) is not None:
            raise AlreadyExistsError(
                f"rollout {event.subject} exists already", "name the new rollout differently"
            )
        for serial, version in event.targets.items():
            CAMERAS.check_target(s, serial, version, "roll out")
        for rig, version in event.rig_targets.items():
            RIGS.check_target(s, rig, version, "roll out")
        for robot in event.canary:
            if _registration(s, robot) is None:
                raise NotFoundError(
                    f"canary robot {robot} is not registered",
                    f"register it first: calibctl fleet add {robot} --serial SERIAL ...",
                )
    elif _rollout(s, event.subject) is None:
        raise NotFoundError(f"no rollout {event.subject}", "`calibctl fleet status` lists the rollouts")


def _activate_rig(s: Session, step: RigActivationStep, event: FleetEvent, signer: Signer | None) -> None:
    RIGS.move(
        s,
        step.rig,
        step.version,
        step.kind,
        event.actor,
        event.station,
        step.reason,
        step.expected_active,
        signer,
    )


def _rollout(s: Session, name: str) -> FleetEvent | None:
    row = s.scalars(
        select(FleetEventRow).where(FleetEventRow.subject == name, FleetEventRow.kind == "rollout").limit(1)
    ).first()
    return None if row is None else decode_fleet_event(row, by_chain=True)


def _check_assignment(s: Session, event: FleetEvent, registered: FleetEvent | None) -> None:
    if registered is None:
        raise NotFoundError(
            f"robot {event.robot} is not registered",
            f"register it first: calibctl fleet add {event.robot} --serial SERIAL ...",
        )
    assert event.version is not None  # the document's own validator
    if event.rig is not None:
        if event.rig not in registered.rigs:
            raise UsageError(
                f"robot {event.robot} does not carry rig {event.rig} (its rigs: "
                f"{', '.join(registered.rigs) or 'none'})",
                "assign one of its own rigs",
            )
        RIGS.check_target(s, event.rig, event.version, "be assigned")
        return
    assert event.serial is not None
    if event.serial not in registered.serials:
        raise UsageError(
            f"robot {event.robot} does not carry {event.serial} (it carries "
            f"{', '.join(registered.serials) or 'no camera serials'})",
            "assign one of its own serials",
        )
    CAMERAS.check_target(s, event.serial, event.version, "be assigned")
