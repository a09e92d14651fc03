"""``calibctl station sync`` / ``status``: the spool's queued units into the central store, in order.

Each record, oldest first, under the spool's sync lock (one syncer per spool):

1. its sha256 and its images' are checked, and its signature when the station has a signing key (a changed
   or, keyed, unsigned record stops the sync there: IntegrityError, exit 1);
2. its images go into the store (content-addressed: storing one again changes nothing);
3. its session is added unless the store has it already (the same content; another is IntegrityError);
4. its calibration is stored as the serial's next version, signed with the station's key when one is
   configured, and made active when accepted - unless the store already holds a calibration of that
   session (``Store.add_artifact_once``: the look and the insert are one transaction under the serial's
   version lock);
5. the record is marked synced with its version.

A kill between any two steps loses nothing and doubles nothing: the next sync redoes steps 2-4 as no-ops
up to where it stopped. Versions come from the store's counter when the calibration is inserted, so a
serial calibrated twice offline gets two consecutive versions in queue order, after whatever the store
held; no version is skipped or reused. The sync stops at the first record it cannot store (store away
again, a changed record) and leaves it and the ones after it queued.

A record the operator sets aside (``set_aside``: one that the sync refuses, or a unit scrapped) stays in the
spool with its images, reason, time and operator, and is never synced: the records behind it are, and its
unit gets no version (the serial's later units take the next ones).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calibctl import bounded
from calibctl.config import Settings
from calibctl.errors import AlreadyExistsError, CalibctlError, IntegrityError, UsageError
from calibctl.store.repository import Store
from calibctl.store.spool import Spool, SpoolRecord, default_spool_path, store_identity
from calibctl.workflows.camera.capture import IMAGE_BATCH
from calibctl.workflows.store_admin.keys import read_trust, signer_of
from calibctl.workflows.store_admin.records import MAX_REASON_CHARS, open_store


@dataclass(frozen=True)
class SyncedUnit:
    seq: int
    serial: str
    session_id: str
    version: int | None  # None: a capture the gates rejected (its session alone was queued)
    status: str  # accepted | rejected | capture rejected
    active: bool
    already: bool  # the store held it already (a sync killed before it marked the record)
    rms_px: float | None = None
    views: int = 0

    def as_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class SyncReport:
    synced: list[SyncedUnit] = field(default_factory=list)
    left: int = 0  # records still queued
    error: CalibctlError | None = None  # what stopped the sync before the queue was empty


def open_spool(settings: Settings, path: Path | None, *, create: bool = True, sign: bool = True) -> Spool:
    """This station's spool for the configured store (exit 2 for another station's or another store's). Keyed
    when the station has a signing key: records queued are signed with it (``sign``: a command that queues
    nothing needs only the public keys) and records are checked against it and the trusted keys."""
    keyed = bool(settings.signing_key)
    return Spool.open(
        path or default_spool_path(settings.station_file, settings.db_url),
        station=settings.station,
        store=store_identity(settings.db_url),
        create=create,
        signer=signer_of(settings) if keyed and sign else None,
        trusted=read_trust(settings) if keyed else None,
    )


def sync(
    settings: Settings, spool: Spool, *, after_store: Callable[[SpoolRecord], None] | None = None
) -> SyncReport:
    """Sync the queued records in order (see the module docstring). ``after_store(record)`` runs after a
    record is in the store and before it is marked synced (where a kill is worst; tests interrupt there)."""
    report = SyncReport()
    if spool.counts()[0] == 0 and not spool.missing():
        return report
    with spool.sync_lock():
        pending = spool.records(pending_only=True)  # what another syncer left, now that it is done
        try:
            with open_store(settings, write=True) as store:
                for record in pending:
                    gap = spool.gap_before(record)
                    if gap is not None:
                        raise gap
                    report.synced.append(_sync_one(settings, spool, store, record))
                    if after_store is not None:
                        after_store(record)
                    spool.mark_synced(record.seq, report.synced[-1].version)
                gap = spool.gap_before(None)  # the newest records deleted
                if gap is not None:
                    raise gap
        except CalibctlError as exc:
            report.error = exc
        report.left = spool.counts()[0]
        spool.prune_images()
    return report


def _sync_one(settings: Settings, spool: Spool, store: Store, record: SpoolRecord) -> SyncedUnit:
    session, artifact = spool.opened(record)
    for start in range(0, len(record.image_shas), IMAGE_BATCH):
        batch = [spool.image_bytes(record, sha) for sha in record.image_shas[start : start + IMAGE_BATCH]]
        store.put_images(batch, retention_days=settings.image_retention_days)
    try:
        store.add_session(session)
    except AlreadyExistsError:
        held = store.get_session(session.session_id)
        if held.model_dump(mode="json") != session.model_dump(mode="json"):
            raise IntegrityError(
                f"the store holds another capture session under the id {session.session_id} of "
                f"spool record {record.seq} ({record.serial}); it and the records after it were not "
                "synced",
                f"compare `calibctl history {record.serial}` with the spool",
            ) from None
    if artifact is None:
        return SyncedUnit(
            record.seq,
            record.serial,
            record.session_id,
            None,
            "capture rejected",
            False,
            False,
            views=len(session.views),
        )
    accepted = artifact.status == "accepted"
    stored, new = store.add_artifact_once(
        artifact,
        activate=accepted,
        actor=artifact.provenance.operator,
        station=settings.station,
        reason=f"solve of session {session.session_id} (queued offline, record {record.seq})",
    )
    active = store.active_version(stored.serial) == stored.version
    return SyncedUnit(
        record.seq,
        record.serial,
        record.session_id,
        stored.version,
        stored.status,
        active,
        not new,
        stored.rms_px,
        len(session.views),
    )


@dataclass(frozen=True)
class QueuedUnit:
    seq: int
    serial: str
    session_id: str
    queued_at: str
    verdict: str  # accepted | rejected (the local solve's lint) | capture rejected
    images: int
    intact: bool  # its sha256 (keyed: its signature) matches; a record that does not is never synced
    problem: str | None = None  # why the sync refuses it

    def as_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class SetAsideUnit:
    """A record set aside: kept in the spool with its images, never synced."""

    seq: int
    serial: str
    session_id: str
    queued_at: str
    set_aside_at: str
    reason: str
    operator: str
    images: int

    def as_json(self) -> dict[str, Any]:
        return dict(self.__dict__)

    @classmethod
    def of(cls, r: SpoolRecord) -> SetAsideUnit:
        return cls(
            r.seq,
            r.serial,
            r.session_id,
            r.queued_at,
            r.set_aside_at or "",
            r.set_aside_reason or "",
            r.set_aside_by or "",
            len(r.image_shas),
        )


@dataclass
class SpoolStatus:
    path: str
    station: str
    store: str
    queued: list[QueuedUnit]
    synced: int
    set_aside: list[SetAsideUnit] = field(default_factory=list)
    missing: list[int] = field(default_factory=list)  # record numbers deleted from the file (not set aside)

    def as_json(self) -> dict[str, Any]:
        return {
            "spool": self.path,
            "station": self.station,
            "store": self.store,
            "synced": self.synced,
            "queued": [q.as_json() for q in self.queued],
            "set_aside": [a.as_json() for a in self.set_aside],
            "missing": self.missing,
        }


def status(spool: Spool) -> SpoolStatus:
    """What is queued (oldest first, each checked as the sync checks it), the records set aside and how many
    records were synced."""
    queued = []
    for r in spool.records(pending_only=True):
        problem = spool.problem(r)
        if problem is None:
            try:
                spool.opened(r)
            except IntegrityError as exc:  # content calibctl did not write, under a matching hash
                problem = exc.message
        queued.append(
            QueuedUnit(
                r.seq,
                r.serial,
                r.session_id,
                r.queued_at,
                "?" if problem else r.verdict(),
                len(r.image_shas),
                problem is None,
                problem,
            )
        )
    aside = sorted([*spool.records(set_aside_only=True), *spool.missing_set_aside()], key=lambda r: r.seq)
    set_aside = [SetAsideUnit.of(r) for r in aside]
    return SpoolStatus(
        str(spool.path), spool.station, spool.store, queued, spool.counts()[1], set_aside, spool.missing()
    )


@dataclass(frozen=True)
class SetAside:
    unit: SetAsideUnit
    queued: int  # records still queued behind and before it

    def as_json(self) -> dict[str, Any]:
        return {**self.unit.as_json(), "still_queued": self.queued}


def set_aside(settings: Settings, spool: Spool, seq: int, reason: str) -> SetAside:
    """Set queued record ``seq`` aside (kept, never synced) with ``reason`` and the operator, under the sync
    lock (refused while a sync runs). Refused (exit 2): no reason, an unknown, synced or set-aside record."""
    if not reason.strip():
        raise UsageError(
            "setting a spool record aside needs a reason", "pass --reason 'why it is not synced'"
        )
    bounded.check_text(reason, "--reason", "the reason")
    if len(reason) > MAX_REASON_CHARS:
        raise UsageError(
            f"the reason is {len(reason)} characters long (at most {MAX_REASON_CHARS})",
            "say why in a sentence or two; put long notes in the ticket the reason names",
        )
    with spool.sync_lock("set nothing aside"):
        record = spool.set_aside(seq, reason=reason, operator=settings.operator)
    return SetAside(SetAsideUnit.of(record), spool.counts()[0])
