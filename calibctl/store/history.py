"""The activation history of a serial, and lookups every artifact operation shares.

These run inside a Store transaction (they take its Session). The active version of a serial is
the version of its latest activation event; events are only ever appended.
"""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.events import ActivationEvent
from calibctl.errors import NotFoundError, StaleActiveVersionError, UsageError, named_list
from calibctl.signing import Signer
from calibctl.store import chain, codec, counters
from calibctl.store.models import ArtifactRow, EventRow, SessionRow

KNOWN_SHOWN = 20  # versions, serials, sessions or boards named in a "not found" message


def check_activation(artifact: CalibrationArtifact, activate: bool, reason: str) -> None:
    if activate and artifact.status != "accepted":
        raise UsageError(
            f"{artifact.serial}: a {artifact.status} calibration can never become active",
            "store it without activating it; fix what lint reported and solve again",
        )
    if activate and not reason.strip():
        raise UsageError("activating a calibration needs a reason")


UNCHECKED = object()
"""``expected_active`` default: the caller did not say which active version it saw (no compare-and-set)."""


def check_rollback(
    label: str,
    to_version: int,
    statuses: dict[int, str],
    active: int | None,
    expected: int | None | object,
    history_command: str,
) -> bool:
    """What every rollback (a camera's or a rig's) checks under its lock before it appends its event:
    ``to_version`` is stored and accepted, and the active version is still the one the caller decided on
    (compare-and-set: ``expected``, None = nothing was active, UNCHECKED = not asked). True when
    ``to_version`` is the active version already: the rollback is done, and no event is appended.
    ``label`` names the subject (``CAM-1``, ``rig R1``); ``history_command`` is the command that shows
    its versions."""
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


def _no_calibration_yet(s: Session, serial: str) -> None:
    """A serial with capture sessions but no calibration is known: say why nothing is stored (NotFoundError)."""
    sessions = s.execute(
        select(SessionRow.session_id, SessionRow.status)
        .where(SessionRow.serial == serial)
        .order_by(SessionRow.started_at, SessionRow.session_id)
    ).all()
    if not sessions:
        return
    listing = named_list([f"{sid} ({st})" for sid, st in sessions], KNOWN_SHOWN)
    if all(st == "rejected" for _, st in sessions):
        raise NotFoundError(
            f"no calibration is stored for '{serial}': its capture sessions were rejected at the gates, so it has "
            f"no accepted version ({listing})",
            f"capture {serial} again with views the gates accept (the capture's gate messages name what was "
            f"missing) with `calibctl calibrate --serial {serial} --board ... --source ...`, or relax a gate that "
            "does not apply at this station in the station file (--station-config, `gates:`)",
        )
    raise NotFoundError(
        f"no calibration is stored for '{serial}': it has capture sessions ({listing}) but none was solved",
        f"solve it: `calibctl solve --serial {serial}`",
    )


def statuses(s: Session, serial: str) -> dict[int, str]:
    """version -> status of ``serial``; NotFoundError listing the known serials when there is none."""
    rows = s.execute(
        select(ArtifactRow.version, ArtifactRow.status)
        .where(ArtifactRow.serial == serial)
        .order_by(ArtifactRow.version)
    ).all()
    if rows:
        return {int(v): str(st) for v, st in rows}
    _no_calibration_yet(s, serial)
    serials = list(s.scalars(select(ArtifactRow.serial).distinct().order_by(ArtifactRow.serial)))
    listing = f"known: {named_list(serials, KNOWN_SHOWN)}" if serials else "no calibrations are stored yet"
    raise NotFoundError(
        f"unknown serial '{serial}'; {listing}", "check the serial, or `calibctl history` another one"
    )


def artifact_row(s: Session, serial: str, version: int) -> ArtifactRow:
    return s.scalars(
        select(ArtifactRow).where(ArtifactRow.serial == serial, ArtifactRow.version == version)
    ).one()


def active_event(s: Session, serial: str) -> EventRow | None:
    """The serial's latest activation event (the one that makes its active version active)."""
    return s.scalars(
        select(EventRow).where(EventRow.serial == serial).order_by(EventRow.id.desc()).limit(1)
    ).first()


def active_in(s: Session, serial: str) -> int | None:
    return s.scalar(
        select(EventRow.version).where(EventRow.serial == serial).order_by(EventRow.id.desc()).limit(1)
    )


def append_event(
    s: Session,
    serial: str,
    version: int,
    kind: str,
    actor: str,
    station: str,
    reason: str,
    signer: Signer | None,
) -> ActivationEvent:
    """Append one event to the store's event log (one hash chain; its counter row is the chain's lock)."""
    counters.next_value(s, "chain", "event")
    row = EventRow(
        serial=serial,
        version=version,
        previous_version=active_in(s, serial),
        kind=kind,
        actor=actor,
        station=station,
        at=utc_now(),
        reason=reason,
    )
    chain.link(s, chain.STREAMS["event"], row, signer)
    s.add(row)
    s.flush()
    return codec.decode_event(row)
