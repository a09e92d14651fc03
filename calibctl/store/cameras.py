"""The cameras' calibration artifacts in the store: versions per serial and their activation log.

The version history itself (allocation, compare-and-set, chained events, lookups) is ``history.CAMERAS``,
the same code as the rigs'; this part adds what only camera artifacts have: the once-per-session add a
station's sync relies on, import under the artifact's own version, and the bulk read of every active one.

Decisions worth knowing:
* ``add_artifact(..., activate=True)`` with a rejected artifact is refused *before anything is
  written* (UsageError): the caller stores rejected artifacts with ``activate=False``.
* ``rollback`` to the version that is already active is done already: nothing is written (None).
* ``import_artifact`` keeps the artifact's version; versions of a serial may then have gaps, and the
  next solve gets (highest version) + 1.
"""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.events import ActivationEvent
from calibctl.errors import AlreadyExistsError, IntegrityError, UnverifiedRecord
from calibctl.store import codec, counters
from calibctl.store.history import CAMERAS, UNCHECKED, check_activation, check_rollback_reason
from calibctl.store.models import ArtifactRow, EventRow
from calibctl.store.runner import Runner


class CameraStore:
    """The Store's camera calibration artifacts."""

    def __init__(self, runner: Runner) -> None:
        self._runner = runner

    def add_artifact(
        self,
        artifact: CalibrationArtifact,
        *,
        activate: bool,
        actor: str,
        station: str,
        reason: str,
        expect_version: int | None = None,
    ) -> CalibrationArtifact:
        """Store ``artifact`` as the serial's next version (sealing its hash) and, when ``activate``,
        make it active. Activating a rejected artifact is refused before anything is written;
        ``expect_version``: refuse (nothing written) unless the next version is that one."""
        check_activation(artifact, activate, reason)
        return self._runner.run(
            lambda s: self._insert_artifact(s, artifact, activate, actor, station, reason, expect_version),
            write=True,
        )

    def add_artifact_once(
        self, artifact: CalibrationArtifact, *, activate: bool, actor: str, station: str, reason: str
    ) -> tuple[CalibrationArtifact, bool]:
        """``add_artifact`` unless the serial already has a calibration solved from the same capture session
        (``provenance.session_id``): then that one, and False. The look and the insert are one
        transaction under the serial's version lock, so a sync run again after a crash never stores a
        calibration twice."""
        check_activation(artifact, activate, reason)

        def work(s: Session) -> tuple[CalibrationArtifact, bool]:
            counters.lock(s, "artifact", artifact.serial)
            row = s.scalars(
                select(ArtifactRow)
                .where(
                    ArtifactRow.serial == artifact.serial,
                    ArtifactRow.session_id == artifact.provenance.session_id,
                )
                .order_by(ArtifactRow.version)
                .limit(1)
            ).first()
            if row is not None:
                return codec.decode_artifact(row, by_chain=True), False
            return self._insert_artifact(s, artifact, activate, actor, station, reason, None), True

        return self._runner.run(work, write=True)

    def _insert_artifact(
        self,
        s: Session,
        artifact: CalibrationArtifact,
        activate: bool,
        actor: str,
        station: str,
        reason: str,
        expect_version: int | None,
    ) -> CalibrationArtifact:
        def build(version: int) -> tuple[CalibrationArtifact, ArtifactRow]:
            stored = artifact.model_copy(update={"version": version}).sealed()
            return stored, codec.artifact_row(stored, utc_now())

        stored, _ = CAMERAS.add(
            s,
            artifact.serial,
            build,
            activate,
            actor,
            station,
            reason,
            self._runner.signer,
            expect_version=expect_version,
        )
        return stored

    def import_artifact(
        self,
        artifact: CalibrationArtifact,
        *,
        actor: str,
        station: str,
        activate: bool,
        reason: str | None = None,
    ) -> CalibrationArtifact:
        """Store an artifact made elsewhere under its own serial@version after checking its hash.
        The same serial@version with the same hash again is a no-op (plus activation when asked)."""
        computed = artifact.computed_sha256()
        if computed != artifact.content_sha256:
            raise IntegrityError(
                f"{artifact.ref} does not match its content_sha256 (recorded {artifact.content_sha256[:12]}, "
                f"content hashes to {computed[:12]}): it was changed after export",
                "re-export it from the store it came from; never edit an artifact by hand",
            )
        why = reason or f"imported {artifact.ref}"
        check_activation(artifact, activate, why)

        def work(s: Session) -> CalibrationArtifact:
            counters.raise_to(s, "artifact", artifact.serial, artifact.version)
            row = s.scalars(
                select(ArtifactRow).where(
                    ArtifactRow.serial == artifact.serial, ArtifactRow.version == artifact.version
                )
            ).first()
            if row is not None:
                if row.content_sha256 != artifact.content_sha256:
                    raise AlreadyExistsError(
                        f"{artifact.ref} already exists in {self._runner.url} with different content "
                        f"(stored sha256 {row.content_sha256[:12]}, imported {artifact.content_sha256[:12]})",
                        "versions are immutable: this store's history for that serial differs from the "
                        "file's",
                    )
                stored = codec.decode_artifact(row)
            else:
                s.add(self._runner.linked("artifact", s, codec.artifact_row(artifact, utc_now())))
                s.flush()
                stored = artifact
            if activate and CAMERAS.active(s, artifact.serial) != artifact.version:
                CAMERAS.append(
                    s, artifact.serial, artifact.version, "activate", actor, station, why, self._runner.signer
                )
            return stored

        return self._runner.run(work, write=True, retry_conflicts=True)

    def get_artifact(self, serial: str, version: int | None = None) -> CalibrationArtifact:
        """``serial@version``; None means the active version. Its record is checked by its chain hash
        (UnverifiedRecord): one sha256 over the stored bytes and columns, content_sha256 included, which a
        writer without the chain cannot change unseen; ``db verify`` and import re-derive content hashes."""

        return self._runner.run(lambda s: CAMERAS.read(s, serial, version, self._runner.served))

    def list_artifacts(self, serial: str) -> list[CalibrationArtifact]:
        """Every version of ``serial``, oldest first (each checked by its chain hash, as ``get_artifact``)."""
        return self._runner.run(lambda s: CAMERAS.documents(s, serial))

    def active_artifacts(
        self,
    ) -> tuple[dict[str, CalibrationArtifact | UnverifiedRecord], dict[str, dict[int, str]]]:
        """The active version of every serial in three bulk queries (no per-serial round trip), each checked
        by its chain hash (an UnverifiedRecord in its place when that fails), and version -> status of
        every serial with nothing active."""

        def work(
            s: Session,
        ) -> tuple[dict[str, CalibrationArtifact | UnverifiedRecord], dict[str, dict[int, str]]]:
            latest = (
                select(EventRow.serial, func.max(EventRow.id).label("id"))
                .group_by(EventRow.serial)
                .subquery()
            )
            active = (
                select(EventRow.serial, EventRow.version).join(latest, EventRow.id == latest.c.id).subquery()
            )
            rows = s.scalars(
                select(ArtifactRow)
                .join(
                    active,
                    (ArtifactRow.serial == active.c.serial) & (ArtifactRow.version == active.c.version),
                )
                .execution_options(yield_per=1000)
            )
            found: dict[str, CalibrationArtifact | UnverifiedRecord] = {}
            events = (
                {}
                if self._runner.trusted is None
                else {
                    e.serial: e for e in s.scalars(select(EventRow).join(latest, EventRow.id == latest.c.id))
                }
            )
            for row in rows:
                try:
                    art = codec.decode_artifact(row, by_chain=True)
                    self._runner.served(s, "artifact", row)
                    self._runner.served(s, "event", events.get(row.serial))
                    if art.status != "accepted":
                        raise UnverifiedRecord(
                            f"the active version of {art.serial} is {art.ref}, which is not accepted: "
                            "the activation log was changed outside calibctl",
                            codec.TAMPER_HINT,
                        )
                    found[row.serial] = art
                except UnverifiedRecord as exc:
                    found[row.serial] = exc
            inactive: dict[str, dict[int, str]] = {}
            listing = select(ArtifactRow.serial, ArtifactRow.version, ArtifactRow.status).order_by(
                ArtifactRow.serial, ArtifactRow.version
            )
            for serial, version, status in s.execute(
                listing.where(ArtifactRow.serial.not_in(select(active.c.serial)))
            ):
                inactive.setdefault(serial, {})[int(version)] = str(status)
            return found, inactive

        return self._runner.run(work)

    def serials(self) -> list[str]:
        return self._runner.run(
            lambda s: list(s.scalars(select(ArtifactRow.serial).distinct().order_by(ArtifactRow.serial)))
        )

    def active_version(self, serial: str) -> int | None:
        """The version of the serial's latest activation event; None when nothing was ever activated."""
        return self._runner.run(lambda s: CAMERAS.active(s, serial))

    def next_version(self, serial: str) -> int:
        """The version the next artifact of ``serial`` would get (nothing is allocated)."""
        return self._runner.run(lambda s: CAMERAS.next_version(s, serial))

    def rollback(
        self,
        serial: str,
        to_version: int,
        *,
        reason: str,
        actor: str,
        station: str,
        expected_active: int | None | object = UNCHECKED,
    ) -> ActivationEvent | None:
        """Make ``to_version`` (accepted, intact) the active version of ``serial``; appends an event.
        None when it is the active version already: done, nothing written.

        Compare-and-set: ``expected_active`` is the active version the caller decided on (None: nothing
        was active); when another writer moved it since, nothing is written (StaleActiveVersionError)."""
        check_rollback_reason(reason)
        return self._runner.run(
            lambda s: CAMERAS.move(
                s,
                serial,
                to_version,
                "rollback",
                actor,
                station,
                reason,
                expected_active,
                self._runner.signer,
            ),
            write=True,
        )

    def events(self, serial: str) -> list[ActivationEvent]:
        """The serial's activation events, oldest first."""
        return self._runner.run(lambda s: CAMERAS.events(s, serial))
