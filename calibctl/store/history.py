"""Version history, written once for every versioned stream: a camera's calibrations (per serial) and a
rig's (per rig name).

A stream is a table of immutable versions plus an append-only log of activation events; the active
version of a subject is the version of its latest event. ``VersionHistory`` holds what differs between
streams (the tables, the subject column, the counter and chain names, the words of its messages) and does
the rest the same way for both: allocating the next version under the subject's counter row (its lock
until commit), compare-and-set on the next version (``expect_version``) or on the active version the
caller built on (``based_on``, ``expected``), appending chained and signed events, and the lookups. The
camera stream is ``CAMERAS`` here; the rig stream is ``rigs.RIGS`` (its decoder lives with the rig code).

Everything here runs inside a Store transaction (it takes the Session).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, NoReturn, TypeVar

from sqlalchemy import select
from sqlalchemy.orm import Session

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.events import ActivationEvent
from calibctl.errors import NotFoundError, StaleActiveVersionError, UnverifiedRecord, UsageError, named_list
from calibctl.signing import Signer
from calibctl.store import chain, codec, counters
from calibctl.store.models import ArtifactRow, EventRow, SessionRow

KNOWN_SHOWN = 20  # versions, serials, sessions or boards named in a "not found" message

V = TypeVar("V")  # the stream's version document
E = TypeVar("E")  # the stream's activation event document
D = TypeVar("D")  # what a caller builds from a new version's number


def check_activation(artifact: CalibrationArtifact, activate: bool, reason: str) -> None:
    if activate and artifact.status != "accepted":
        raise UsageError(
            f"{artifact.serial}: a {artifact.status} calibration can never become active",
            "store it without activating it; fix what lint reported and solve again",
        )
    if activate and not reason.strip():
        raise UsageError("activating a calibration needs a reason")


def check_rollback_reason(reason: str) -> None:
    if not reason.strip():
        raise UsageError("a rollback needs a reason", "pass --reason 'why this version'")


UNCHECKED = object()
"""``expected_active`` / ``based_on`` default: the caller did not say which active version it saw."""


def check_rollback(
    label: str,
    to_version: int,
    statuses: dict[int, str],
    active: int | None,
    expected: int | None | object,
    history_command: str,
) -> bool:
    """What every move of an active version (a rollback, a fleet step) checks under its lock before it
    appends its event: ``to_version`` is stored and accepted, and the active version is still the one the
    caller decided on (compare-and-set: ``expected``, None = nothing was active, UNCHECKED = not asked).
    True when ``to_version`` is the active version already: nothing is to be appended.
    ``label`` names the subject (``CAM-1``, ``rig R1``); ``history_command`` shows its versions."""
    if to_version not in statuses:
        raise NotFoundError(
            f"{label} has no version {to_version}; versions: {named_list(list(statuses), KNOWN_SHOWN)}",
            f"see `{history_command}`",
        )
    if statuses[to_version] != "accepted":
        accepted = [v for v, st in statuses.items() if st == "accepted"]
        listing = (
            f"accepted versions: {named_list(accepted, KNOWN_SHOWN)}"
            if accepted
            else "no version is accepted"
        )
        raise UsageError(f"{label}@{to_version} is rejected and can never become active; {listing}")
    if expected is not UNCHECKED and expected != active:
        seen = f"v{expected}" if expected is not None else "no active version"
        now = f"v{active}" if active is not None else "no active version"
        raise StaleActiveVersionError(
            f"{label}: the active version changed underneath this rollback (it saw {seen}, it is now {now}); "
            f"nothing rolled back to v{to_version}",
            f"look at `{history_command}` and roll back again if v{to_version} is still what you want",
        )
    return active == to_version


@dataclass(frozen=True)
class VersionHistory(Generic[V, E]):
    """One versioned stream. ``scope`` is both its counter scope and its chain stream (``artifact``,
    ``rig``); ``event_stream`` its event log's chain stream and ``("chain", event_stream)`` counter."""

    scope: str
    version_model: Any  # ArtifactRow | RigCalibrationRow
    event_model: Any  # EventRow | RigEventRow
    key: str  # the subject column of both tables
    event_stream: str
    label: Callable[[str], str]  # the subject in messages: "CAM-1", "rig R1"
    history_command: Callable[[str], str]  # what lists the subject's versions
    placeholder: str  # the subject in generic hints: "SERIAL", "RIG"
    decode: Callable[[Any], V]  # a version row's document; UnverifiedRecord when it was tampered with
    decode_event: Callable[[Any], E]
    no_versions: Callable[[Session, str], NoReturn]  # the NotFoundError of a subject with no version
    solve_again: Callable[[str], str]  # the hint's first words when no version is accepted
    active_must_be_accepted: bool  # a forged log making a rejected version active is an UnverifiedRecord

    def _of(self, model: Any, key: str) -> Any:
        return getattr(model, self.key) == key

    # reads -----------------------------------------------------------------------------------------

    def statuses(self, s: Session, key: str) -> dict[int, str]:
        """version -> status of ``key``; ``no_versions`` raises when it has none."""
        m = self.version_model
        rows = s.execute(select(m.version, m.status).where(self._of(m, key)).order_by(m.version)).all()
        if rows:
            return {int(v): str(st) for v, st in rows}
        self.no_versions(s, key)

    def row(self, s: Session, key: str, version: int) -> Any:
        m = self.version_model
        return s.scalars(select(m).where(self._of(m, key), m.version == version)).one()

    def documents(self, s: Session, key: str) -> list[V]:
        """Every version of ``key``, oldest first, each decoded (NotFoundError when it has none)."""
        self.statuses(s, key)
        m = self.version_model
        return [self.decode(r) for r in s.scalars(select(m).where(self._of(m, key)).order_by(m.version))]

    def active_event(self, s: Session, key: str) -> Any:
        """The latest activation event of ``key`` (the one that makes its active version active), or None."""
        m = self.event_model
        return s.scalars(select(m).where(self._of(m, key)).order_by(m.id.desc()).limit(1)).first()

    def active(self, s: Session, key: str) -> int | None:
        m = self.event_model
        return s.scalar(select(m.version).where(self._of(m, key)).order_by(m.id.desc()).limit(1))

    def events(self, s: Session, key: str) -> list[E]:
        """The activation events of ``key``, oldest first."""
        m = self.event_model
        return [self.decode_event(r) for r in s.scalars(select(m).where(self._of(m, key)).order_by(m.id))]

    def next_version(self, s: Session, key: str) -> int:
        """The version the next one of ``key`` would get (nothing is allocated)."""
        return (counters.peek(s, self.scope, key) or 0) + 1

    def resolve(self, s: Session, key: str, version: int | None) -> int:
        """``version``, or the active one when None, once it is known to be stored (NotFoundError listing
        the versions otherwise; UnverifiedRecord when the log makes a non-accepted version active)."""
        statuses = self.statuses(s, key)
        label, command = self.label(key), self.history_command(key)
        wanted = self.active(s, key) if version is None else version
        if wanted is None:
            listing = named_list([f"{v} ({st})" for v, st in statuses.items()], KNOWN_SHOWN)
            raise NotFoundError(
                f"{label} has no active version; versions: {listing}",
                f"ask for a version ({key}@N) or roll back to an accepted one"
                if "accepted" in statuses.values()
                else f"none is accepted: {self.solve_again(key)}, or ask for a version ({key}@N) to "
                "inspect it",
            )
        if version is None and self.active_must_be_accepted and statuses.get(wanted) != "accepted":
            raise UnverifiedRecord(  # only possible if the event log was forged
                f"the active version of {label} is {key}@{wanted}, which is not accepted: "
                "the activation log was changed outside calibctl",
                codec.TAMPER_HINT,
            )
        if wanted not in statuses:
            raise NotFoundError(
                f"{label} has no version {wanted}; versions: {named_list(list(statuses), KNOWN_SHOWN)}",
                f"see `{command}`",
            )
        return wanted

    def read(
        self,
        s: Session,
        key: str,
        version: int | None,
        served: Callable[[Session, str, Any], None],
    ) -> V:
        """``key@version`` (None: the active one) decoded (its integrity checked), then ``served`` (with keys
        configured, refused if ``db verify`` would flag it), and so is the event making it active."""
        row = self.row(s, key, self.resolve(s, key, version))
        document = self.decode(row)
        served(s, self.scope, row)
        if version is None:
            served(s, self.event_stream, self.active_event(s, key))
        return document

    def check_target(self, s: Session, key: str, version: int, what: str) -> None:
        """``key@version`` is stored and accepted, so a robot may run it (``what``: "roll out", ...)."""
        known = self.statuses(s, key)
        status = known.get(version)
        label = self.label(key)
        if status is None:
            raise NotFoundError(
                f"{label} has no version {version}; versions: {', '.join(str(v) for v in sorted(known))}",
                f"see `{self.history_command(key)}`",
            )
        if status != "accepted":
            raise UsageError(
                f"{label}@{version} is {status}: a robot must not run it, so it cannot {what}",
                f"name an accepted version (`{self.history_command(self.placeholder)}`)",
            )

    # writes ----------------------------------------------------------------------------------------

    def append(
        self,
        s: Session,
        key: str,
        version: int,
        kind: str,
        actor: str,
        station: str,
        reason: str,
        signer: Signer | None,
    ) -> E:
        """Append one event to the stream's event log (one hash chain; its counter row is its lock)."""
        counters.next_value(s, "chain", self.event_stream)
        row = self.event_model(
            **{self.key: key},
            version=version,
            previous_version=self.active(s, key),
            kind=kind,
            actor=actor,
            station=station,
            at=utc_now(),
            reason=reason,
        )
        chain.link(s, chain.STREAMS[self.event_stream], row, signer)
        s.add(row)
        s.flush()
        return self.decode_event(row)

    def add(
        self,
        s: Session,
        key: str,
        build: Callable[[int], tuple[D, Any]],
        activate: bool,
        actor: str,
        station: str,
        reason: str,
        signer: Signer | None,
        *,
        expect_version: int | None = None,
        based_on: int | None | object = UNCHECKED,
    ) -> tuple[D, Any]:
        """Store ``key``'s next version (``build(version)``: the document and its row) and activate it when
        asked. Compare-and-set, nothing written on a mismatch: ``expect_version`` is the version the caller
        wants (UsageError), ``based_on`` the active version it built on (StaleActiveVersionError)."""
        version = counters.next_value(s, self.scope, key)  # the subject's lock until this transaction ends
        if expect_version is not None and version != expect_version:
            raise UsageError(
                f"{key}@{expect_version} cannot be stored: this store's next version "
                f"of {key} is {version} (another was stored meanwhile); nothing was written",
                "run the command again",
            )
        if based_on is not UNCHECKED:
            active = self.active(s, key)
            if active != based_on:
                seen = f"{key}@{based_on}" if based_on is not None else "no active version"
                raise StaleActiveVersionError(
                    f"{self.label(key)}: the active version changed underneath this write (it was built on "
                    f"{seen}, the active version is now {key}@{active}); nothing stored",
                    f"look at `{self.history_command(key)}` and run the command again on {key}@{active}",
                )
        document, row = build(version)
        chain.link(s, chain.STREAMS[self.scope], row, signer)
        s.add(row)
        s.flush()
        if activate:
            self.append(s, key, version, "activate", actor, station, reason, signer)
        return document, row

    def move(
        self,
        s: Session,
        key: str,
        to_version: int,
        kind: str,
        actor: str,
        station: str,
        reason: str,
        expected: int | None | object,
        signer: Signer | None,
    ) -> E | None:
        """Make ``to_version`` (accepted, intact) the active version (a rollback, or a fleet step's
        activation): checked under the subject's lock, compare-and-set on ``expected``. None when it is
        the active version already: done, nothing written."""
        counters.lock(s, self.scope, key)
        already = check_rollback(
            self.label(key),
            to_version,
            self.statuses(s, key),
            self.active(s, key),
            expected,
            self.history_command(key),
        )
        self.decode(self.row(s, key, to_version))  # never activate tampered bytes
        if already:
            return None
        return self.append(s, key, to_version, kind, actor, station, reason, signer)


def _no_calibration(s: Session, serial: str) -> NoReturn:
    """A serial without calibrations: say why (its capture sessions were rejected, or never solved) or list
    the serials that have some (NotFoundError)."""
    sessions = s.execute(
        select(SessionRow.session_id, SessionRow.status)
        .where(SessionRow.serial == serial)
        .order_by(SessionRow.started_at, SessionRow.session_id)
    ).all()
    if sessions:
        listing = named_list([f"{sid} ({st})" for sid, st in sessions], KNOWN_SHOWN)
        if all(st == "rejected" for _, st in sessions):
            raise NotFoundError(
                f"no calibration is stored for '{serial}': its capture sessions were rejected at the gates, "
                f"so it has no accepted version ({listing})",
                f"capture {serial} again with views the gates accept (the capture's gate messages name "
                f"what was missing) with `calibctl calibrate --serial {serial} --board ... --source ...`, or "
                "relax a gate that does not apply at this station in the station file (--station-config, "
                "`gates:`)",
            )
        raise NotFoundError(
            f"no calibration is stored for '{serial}': it has capture sessions ({listing}) but none was "
            "solved",
            f"solve it: `calibctl solve --serial {serial}`",
        )
    serials = list(s.scalars(select(ArtifactRow.serial).distinct().order_by(ArtifactRow.serial)))
    listing = f"known: {named_list(serials, KNOWN_SHOWN)}" if serials else "no calibrations are stored yet"
    raise NotFoundError(
        f"unknown serial '{serial}'; {listing}", "check the serial, or `calibctl history` another one"
    )


CAMERAS: VersionHistory[CalibrationArtifact, ActivationEvent] = VersionHistory(
    scope="artifact",
    version_model=ArtifactRow,
    event_model=EventRow,
    key="serial",
    event_stream="event",
    label=lambda serial: serial,
    history_command=lambda serial: f"calibctl history {serial}",
    placeholder="SERIAL",
    decode=lambda row: codec.decode_artifact(row, by_chain=True),
    decode_event=codec.decode_event,
    no_versions=_no_calibration,
    solve_again=lambda serial: f"recalibrate it (`calibctl calibrate --serial {serial} ...`)",
    active_must_be_accepted=True,
)
"""The cameras' calibrations: versions per serial, one activation log for the store."""
