"""Rigs in the store: definitions, rig sessions, rig calibrations (versioned per rig) and their
append-only activation log. Same rules as the camera tables: every read re-checks the sha256, rows are
immutable in the database (revision 0003's triggers), the active version is the latest event's, and
versions (per rig) and activation events (one log) are hash-chained and signed like the cameras'
(revision 0007, ``chain.STREAMS["rig"]`` and ``["rig_event"]``), and so are the definitions (revision
0008, ``["rig_definition"]``, one log). Rig sessions are not chained, like the cameras' capture
sessions (docs/trust.md says why).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

from sqlalchemy import select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.errors import (
    AlreadyExistsError,
    IntegrityError,
    NotFoundError,
    StaleActiveVersionError,
    UsageError,
    named_list,
)
from calibctl.signing import Signer
from calibctl.store import chain, codec, counters
from calibctl.store.history import KNOWN_SHOWN, UNCHECKED, check_rollback
from calibctl.store.models import RigCalibrationRow, RigEventRow, RigRow, RigSessionRow, SessionRow

if TYPE_CHECKING:  # the rig models are built when a rig is read or written, not by every store command
    from calibctl.artifacts.rig import RigActivation, RigCalibration, RigDefinition, RigSession
    from calibctl.artifacts.session import CaptureSession

T = TypeVar("T")


def _decode_hashed(model: type[Any], payload: str, recorded: str, what: str) -> Any:
    actual = sha256_hex(payload.encode("utf-8"))
    if actual != recorded:
        raise codec._mismatch(what, recorded, actual)
    return codec._parse(model, payload, what)


def decode_definition(row: RigRow, *, by_chain: bool = False) -> RigDefinition:
    """The stored definition after its payload hash check and, ``by_chain`` (every read), its chain hash:
    a design tolerance widened with the payload hash recomputed is refused before rig lint trusts it."""
    from calibctl.artifacts.rig import RigDefinition

    if by_chain:
        problem = chain.row_problem(chain.STREAMS["rig_definition"], row)
        if problem is not None:
            raise IntegrityError(problem, codec.TAMPER_HINT)
    rig: RigDefinition = _decode_hashed(RigDefinition, row.payload, row.payload_sha256, f"rig {row.name}")
    if rig.name != row.name:
        raise IntegrityError(
            f"rig {row.name}: the stored name disagrees with the stored document", codec.TAMPER_HINT
        )
    return rig


def decode_calibration(row: RigCalibrationRow) -> RigCalibration:
    from calibctl.artifacts.rig import RigCalibration

    what = f"rig {row.rig}@{row.version}"
    cal: RigCalibration = codec._parse(RigCalibration, row.payload, what)
    actual = cal.computed_sha256()
    if actual != row.content_sha256:
        raise codec._mismatch(what, row.content_sha256, actual)
    codec._check_columns(
        what,
        {
            "rig": (row.rig, cal.rig),
            "version": (row.version, cal.version),
            "status": (row.status, cal.status),
        },
    )
    return codec.with_signature(
        cal.model_copy(update={"signature": None}), row, what
    )  # the row's, never the payload's


def _event(row: RigEventRow) -> RigActivation:
    from calibctl.artifacts.rig import RigActivation

    return RigActivation(
        event_id=row.id,
        rig=row.rig,
        version=row.version,
        previous_version=row.previous_version,
        kind=row.kind,
        actor=row.actor,
        station=row.station,
        at=row.at,
        reason=row.reason,
    )


def rig_calibration_row(s: Session, rig: str, version: int) -> RigCalibrationRow:
    return s.scalars(
        select(RigCalibrationRow).where(RigCalibrationRow.rig == rig, RigCalibrationRow.version == version)
    ).one()


def _active(s: Session, rig: str) -> int | None:
    return s.scalar(
        select(RigEventRow.version).where(RigEventRow.rig == rig).order_by(RigEventRow.id.desc()).limit(1)
    )


def _append(
    s: Session,
    rig: str,
    version: int,
    kind: str,
    actor: str,
    station: str,
    reason: str,
    signer: Signer | None,
) -> RigActivation:
    """Append one event to the store's rig event log (one hash chain; its counter row is the chain's lock)."""
    counters.next_value(s, "chain", "rig_event")
    row = RigEventRow(
        rig=rig,
        version=version,
        previous_version=_active(s, rig),
        kind=kind,
        actor=actor,
        station=station,
        at=utc_now(),
        reason=reason,
    )
    chain.link(s, chain.STREAMS["rig_event"], row, signer)
    s.add(row)
    s.flush()
    return _event(row)


def _statuses(s: Session, rig: str) -> dict[int, str]:
    rows = s.execute(
        select(RigCalibrationRow.version, RigCalibrationRow.status)
        .where(RigCalibrationRow.rig == rig)
        .order_by(RigCalibrationRow.version)
    ).all()
    if rows:
        return {int(v): str(st) for v, st in rows}
    raise NotFoundError(
        f"rig {rig} has no calibration yet", f"run `calibctl rig solve {rig}` after a rig capture"
    )


class RigStoreMixin:
    """Rig methods of ``Store`` (which provides ``_run``)."""

    _run: Callable[..., Any]
    _served: Callable[[Session, str, Any], None]
    _session_linked: Callable[[Session, SessionRow], SessionRow]
    signer: Signer | None

    # definitions ---------------------------------------------------------------------------------

    def add_rig(self, rig: RigDefinition) -> RigDefinition:
        """Register a rig; a name is registered once (AlreadyExistsError)."""
        payload = codec.canonical_text(rig)

        def work(s: Session) -> RigDefinition:
            position = counters.next_value(s, "chain", "rig_definition")  # the stream's lock until commit
            if s.get(RigRow, rig.name) is not None:
                raise AlreadyExistsError(
                    f"rig {rig.name} is already registered",
                    "rig definitions are immutable: register the new layout under a new name",
                )
            row = RigRow(
                name=rig.name,
                id=position,
                created_at=rig.created_at,
                payload=payload,
                payload_sha256=sha256_hex(payload.encode("utf-8")),
            )
            chain.link(s, chain.STREAMS["rig_definition"], row, self.signer)
            s.add(row)
            return rig

        return self._run(work, write=True)

    def get_rig(self, name: str) -> RigDefinition:
        def work(s: Session) -> RigDefinition:
            row = s.get(RigRow, name)
            if row is None:
                known = list(s.scalars(select(RigRow.name).order_by(RigRow.name)))
                listing = f"known: {named_list(known, KNOWN_SHOWN)}" if known else "no rig is registered yet"
                raise NotFoundError(f"unknown rig '{name}'; {listing}", "register it with `calibctl rig add`")
            return decode_definition(row, by_chain=True)

        return self._run(work)

    # sessions ------------------------------------------------------------------------------------

    def add_rig_session(self, session: RigSession, members: Sequence[CaptureSession] = ()) -> None:
        """Store a rig session together with its ``members``' capture sessions, in one transaction: every
        one of them or none (a rig capture that fails half-way leaves no member session behind)."""
        payload = codec.canonical_text(session)

        def work(s: Session) -> None:
            for member in members:
                if s.get(SessionRow, member.session_id) is not None:
                    raise AlreadyExistsError(f"capture session {member.session_id} is already stored")
                s.add(self._session_linked(s, codec.session_row(member)))  # chained like any session (0009)
            s.add(
                RigSessionRow(
                    rig_session_id=session.rig_session_id,
                    rig=session.rig,
                    status=session.status,
                    created_at=session.created_at,
                    payload=payload,
                    payload_sha256=sha256_hex(payload.encode("utf-8")),
                )
            )
            s.flush()

        self._run(work, write=True, retry_conflicts=True)

    def get_rig_session(self, rig: str, rig_session_id: str | None = None) -> RigSession:
        """A rig session by id, or the rig's latest accepted one."""
        from calibctl.artifacts.rig import RigSession

        def work(s: Session) -> RigSession:
            q = select(RigSessionRow).where(RigSessionRow.rig == rig)
            if rig_session_id is not None:
                q = q.where(RigSessionRow.rig_session_id == rig_session_id)
            else:
                q = q.where(RigSessionRow.status == "accepted")
            row = s.scalars(q.order_by(RigSessionRow.created_at.desc()).limit(1)).first()
            if row is None:
                what = f"rig session {rig_session_id}" if rig_session_id else "an accepted rig session"
                raise NotFoundError(
                    f"rig {rig} has no {what}", f"run `calibctl rig capture {rig} --source ...` first"
                )
            out: RigSession = _decode_hashed(
                RigSession, row.payload, row.payload_sha256, f"rig session {row.rig_session_id}"
            )
            return out

        return self._run(work)

    # calibrations --------------------------------------------------------------------------------

    def add_rig_calibration(
        self,
        cal: RigCalibration,
        *,
        activate: bool,
        actor: str,
        station: str,
        reason: str,
        based_on: int | None | object = UNCHECKED,
    ) -> RigCalibration:
        """Store as the rig's next version (sealed) and activate when asked (accepted only).

        Compare-and-set: ``based_on`` is the active version ``cal`` was derived from (a hand-eye edge
        added to it); when another writer moved the rig's active version since, nothing is written
        (StaleActiveVersionError naming the newer version)."""
        if activate and cal.status != "accepted":
            raise UsageError(f"rig {cal.rig}: a {cal.status} calibration can never become active")

        def work(s: Session) -> RigCalibration:
            version = counters.next_value(s, "rig", cal.rig)  # the rig's lock until this transaction ends
            active = _active(s, cal.rig)
            if based_on is not UNCHECKED and active != based_on:
                seen = f"{cal.rig}@{based_on}" if based_on is not None else "no active version"
                raise StaleActiveVersionError(
                    f"rig {cal.rig}: the active version changed underneath this write (it was built on {seen}, "
                    f"the active version is now {cal.rig}@{active}); nothing stored",
                    f"look at `calibctl rig history {cal.rig}` and run the command again on {cal.rig}@{active}",
                )
            stored = cal.model_copy(
                update={"version": version}
            ).sealed()  # sealed drops an imported signature
            row = RigCalibrationRow(
                rig=stored.rig,
                version=version,
                status=stored.status,
                created_at=stored.provenance.created_at,
                payload=codec.canonical_text(stored),
                content_sha256=stored.content_sha256,
            )
            chain.link(s, chain.STREAMS["rig"], row, self.signer)
            s.add(row)
            s.flush()
            if activate:
                _append(s, stored.rig, version, "activate", actor, station, reason, self.signer)
            return codec.with_signature(stored, row, f"rig {stored.rig}@{version}")

        return self._run(work, write=True)

    def get_rig_calibration(self, rig: str, version: int | None = None) -> RigCalibration:
        """``rig@version``; None means the active version."""

        def work(s: Session) -> RigCalibration:
            statuses = _statuses(s, rig)
            wanted = _active(s, rig) if version is None else version
            if wanted is None:
                listing = named_list([f"{v} ({st})" for v, st in statuses.items()], KNOWN_SHOWN)
                raise NotFoundError(
                    f"rig {rig} has no active version; versions: {listing}",
                    f"ask for a version ({rig}@N) or roll back to an accepted one"
                    if "accepted" in statuses.values()
                    else f"none is accepted: solve the rig again (`calibctl rig solve {rig}`, after a new `calibctl rig "
                    f"capture` if its lint blames the capture), or ask for a version ({rig}@N) to inspect it",
                )
            if wanted not in statuses:
                raise NotFoundError(
                    f"rig {rig} has no version {wanted}; versions: {named_list(list(statuses), KNOWN_SHOWN)}",
                    f"see `calibctl rig history {rig}`",
                )
            row = s.scalars(
                select(RigCalibrationRow).where(
                    RigCalibrationRow.rig == rig, RigCalibrationRow.version == wanted
                )
            ).one()
            cal = decode_calibration(row)
            self._served(s, "rig", row)
            if version is None:  # the event that makes it active is served too
                self._served(
                    s,
                    "rig_event",
                    s.scalars(
                        select(RigEventRow)
                        .where(RigEventRow.rig == rig)
                        .order_by(RigEventRow.id.desc())
                        .limit(1)
                    ).first(),
                )
            return cal

        return self._run(work)

    def list_rig_calibrations(self, rig: str) -> list[RigCalibration]:
        def work(s: Session) -> list[RigCalibration]:
            _statuses(s, rig)
            rows = s.scalars(
                select(RigCalibrationRow)
                .where(RigCalibrationRow.rig == rig)
                .order_by(RigCalibrationRow.version)
            )
            return [decode_calibration(r) for r in rows]

        return self._run(work)

    def active_rig_version(self, rig: str) -> int | None:
        return self._run(lambda s: _active(s, rig))

    def rollback_rig(
        self,
        rig: str,
        to_version: int,
        *,
        reason: str,
        actor: str,
        station: str,
        expected_active: int | None | object = UNCHECKED,
    ) -> RigActivation | None:
        """Make ``rig@to_version`` (accepted, intact) the rig's active version; appends an event (None when
        it is the active version already: done, nothing written).

        Compare-and-set like the cameras' ``Store.rollback``: ``expected_active`` is the active version the
        caller decided on (None: nothing was active); when another writer moved it since (a solve, a
        hand-eye edge, another rollback), nothing is written (StaleActiveVersionError naming the newer one)."""
        if not reason.strip():
            raise UsageError("a rollback needs a reason", "pass --reason 'why this version'")

        def work(s: Session) -> RigActivation | None:
            counters.lock(s, "rig", rig)
            already = check_rollback(
                f"rig {rig}",
                to_version,
                _statuses(s, rig),
                _active(s, rig),
                expected_active,
                f"calibctl rig history {rig}",
            )
            decode_calibration(rig_calibration_row(s, rig, to_version))
            if already:
                return None
            return _append(s, rig, to_version, "rollback", actor, station, reason, self.signer)

        return self._run(work, write=True)

    def rig_events(self, rig: str) -> list[RigActivation]:
        return self._run(
            lambda s: [
                _event(r)
                for r in s.scalars(select(RigEventRow).where(RigEventRow.rig == rig).order_by(RigEventRow.id))
            ]
        )


active_rig, append_rig_event, rig_statuses = (
    _active,
    _append,
    _statuses,
)  # for the fleet's rig steps (store.fleet)


def rig_member_session_ids(s: Session) -> set[str]:
    """The capture sessions taken as members of a rig capture (every rig session's camera_sessions).
    Read from the rig sessions themselves, so stores written before this rule keep working unchanged."""
    ids: set[str] = set()
    for payload in s.scalars(select(RigSessionRow.payload)):
        try:
            ids.update(str(v) for v in json.loads(payload).get("camera_sessions", {}).values())
        except (ValueError, AttributeError):
            continue  # a damaged row is verify's to report; it names no member here
    return ids
