"""Rigs in the store: definitions, rig sessions, rig calibrations (versioned per rig) and their
append-only activation log. Same rules as the camera tables: every read re-checks the sha256, rows are
immutable in the database (revision 0003's triggers), the active version is the latest event's, and
versions (per rig) and activation events (one log) are hash-chained and signed like the cameras'
(revision 0007, ``chain.STREAMS["rig"]`` and ``["rig_event"]``), and so are the definitions (revision
0008, ``["rig_definition"]``, one log). Rig sessions are not chained, like the cameras' capture
sessions (docs/trust.md says why). The version history itself is ``RIGS``, a ``history.VersionHistory``:
the same code as the cameras', so a rig rollback, a hand-eye edge's compare-and-set and a fleet step
behave as a camera's do.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NoReturn

from sqlalchemy import select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex
from calibctl.errors import (
    AlreadyExistsError,
    NotFoundError,
    UnverifiedRecord,
    UsageError,
    named_list,
)
from calibctl.store import chain, codec, counters
from calibctl.store.history import KNOWN_SHOWN, UNCHECKED, VersionHistory, check_rollback_reason
from calibctl.store.models import RigCalibrationRow, RigEventRow, RigRow, RigSessionRow, SessionRow
from calibctl.store.runner import Runner

if TYPE_CHECKING:  # the rig models are built when a rig is read or written, not by every store command
    from calibctl.artifacts.rig import RigActivation, RigCalibration, RigDefinition, RigSession
    from calibctl.artifacts.session import CaptureSession


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
        codec.chain_checked("rig_definition", row)
    rig: RigDefinition = _decode_hashed(RigDefinition, row.payload, row.payload_sha256, f"rig {row.name}")
    if rig.name != row.name:
        raise UnverifiedRecord(
            f"rig {row.name}: the stored name disagrees with the stored document", codec.TAMPER_HINT
        )
    return rig


def decode_calibration(row: RigCalibrationRow, *, by_chain: bool = False) -> RigCalibration:
    """The stored rig version after its content hash check (re-derived from the parsed document) and,
    ``by_chain`` (every read), its chain hash: an edge edited with only the content hash recomputed is
    refused, as a camera's calibration is."""
    from calibctl.artifacts.rig import RigCalibration

    what = f"rig {row.rig}@{row.version}"
    cal: RigCalibration = codec._parse(RigCalibration, row.payload, what)
    actual = cal.computed_sha256()
    if actual != row.content_sha256:
        raise codec._mismatch(what, row.content_sha256, actual)
    if by_chain:
        codec.chain_checked("rig", row)
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


def _no_calibration(s: Session, rig: str) -> NoReturn:
    raise NotFoundError(
        f"rig {rig} has no calibration yet",
        f"run `calibctl rig solve {rig}` after a rig capture (a one-camera rig needs none)",
    )


RIGS: VersionHistory[RigCalibration, RigActivation] = VersionHistory(
    scope="rig",
    version_model=RigCalibrationRow,
    event_model=RigEventRow,
    key="rig",
    event_stream="rig_event",
    label=lambda rig: f"rig {rig}",
    history_command=lambda rig: f"calibctl rig history {rig}",
    placeholder="RIG",
    decode=lambda row: decode_calibration(row, by_chain=True),
    decode_event=codec.decode_rig_event,
    no_versions=_no_calibration,
    solve_again=lambda rig: (
        f"solve the rig again (`calibctl rig solve {rig}`, after a new `calibctl rig capture` if its lint "
        "blames the capture)"
    ),
    active_must_be_accepted=False,
)
"""The rigs' calibrations: versions per rig, one activation log for the store."""


class RigStore:
    """The Store's rigs: definitions, rig sessions and versioned rig calibrations."""

    def __init__(self, runner: Runner, session_linked: Callable[[Session, SessionRow], SessionRow]) -> None:
        self._runner = runner
        self._session_linked = session_linked  # the member capture sessions are numbered and chained

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
            chain.link(s, chain.STREAMS["rig_definition"], row, self._runner.signer)
            s.add(row)
            return rig

        return self._runner.run(work, write=True)

    def get_rig(self, name: str) -> RigDefinition:
        def work(s: Session) -> RigDefinition:
            row = s.get(RigRow, name)
            if row is None:
                known = list(s.scalars(select(RigRow.name).order_by(RigRow.name)))
                listing = f"known: {named_list(known, KNOWN_SHOWN)}" if known else "no rig is registered yet"
                raise NotFoundError(f"unknown rig '{name}'; {listing}", "register it with `calibctl rig add`")
            return decode_definition(row, by_chain=True)

        return self._runner.run(work)

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

        self._runner.run(work, write=True, retry_conflicts=True)

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

        return self._runner.run(work)

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

        def build(version: int) -> tuple[RigCalibration, RigCalibrationRow]:
            stored = cal.model_copy(update={"version": version}).sealed()  # drops an imported signature
            return stored, RigCalibrationRow(
                rig=stored.rig,
                version=version,
                status=stored.status,
                created_at=stored.provenance.created_at,
                payload=codec.canonical_text(stored),
                content_sha256=stored.content_sha256,
            )

        def work(s: Session) -> RigCalibration:
            stored, row = RIGS.add(
                s, cal.rig, build, activate, actor, station, reason, self._runner.signer, based_on=based_on
            )
            return codec.with_signature(stored, row, f"rig {stored.rig}@{stored.version}")

        return self._runner.run(work, write=True)

    def get_rig_calibration(self, rig: str, version: int | None = None) -> RigCalibration:
        """``rig@version``; None means the active version."""

        return self._runner.run(lambda s: RIGS.read(s, rig, version, self._runner.served))

    def list_rig_calibrations(self, rig: str) -> list[RigCalibration]:
        return self._runner.run(lambda s: RIGS.documents(s, rig))

    def active_rig_version(self, rig: str) -> int | None:
        return self._runner.run(lambda s: RIGS.active(s, rig))

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
        hand-eye edge, another rollback), nothing is written (StaleActiveVersionError naming the newer
        one)."""
        check_rollback_reason(reason)
        return self._runner.run(
            lambda s: RIGS.move(
                s, rig, to_version, "rollback", actor, station, reason, expected_active, self._runner.signer
            ),
            write=True,
        )

    def rig_events(self, rig: str) -> list[RigActivation]:
        return self._runner.run(lambda s: RIGS.events(s, rig))


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
