"""The Store: boards, capture sessions, calibration artifacts, activation events and images.

Every public method is one transaction and returns contract documents (pydantic), never ORM rows.
Every read of a document re-checks its hash (IntegrityError naming it on mismatch): a calibration
artifact by its record's chain hash (covering its bytes and content_sha256), the others by their
sha256; ``db verify`` and import also re-derive an artifact's content hash. The active
version of a serial is not a mutable pointer: it is the version of the serial's latest activation
event, and events are append-only (database triggers refuse UPDATE/DELETE).

Decisions worth knowing:
* ``add_artifact(..., activate=True)`` with a rejected artifact is refused *before anything is
  written* (UsageError): the caller stores rejected artifacts with ``activate=False``.
* ``rollback`` to the version that is already active is refused (UsageError): nothing would move.
* ``import_artifact`` keeps the artifact's version; versions of a serial may then have gaps, and the
  next solve gets (highest version) + 1.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, TypeVar

from sqlalchemy import Engine, func, select, text
from sqlalchemy import exc as sa_exc
from sqlalchemy.orm import Session

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.events import ActivationEvent
from calibctl.artifacts.session import CaptureSession
from calibctl.errors import (
    AlreadyExistsError,
    DatabaseError,
    IntegrityError,
    NotFoundError,
    UsageError,
    named_list,
)
from calibctl.signing import Signer, TrustedKeys
from calibctl.store import chain, codec, counters, history, images, migrate, served
from calibctl.store.checks import CheckStoreMixin
from calibctl.store.engine import (
    WRITE_OPTION,
    as_database_error,
    display_url,
    is_retryable,
    is_unique_violation,
    sqlite_path,
)
from calibctl.store.engine import make_engine as _make_engine
from calibctl.store.fleet import FleetStoreMixin
from calibctl.store.health import HealthStoreMixin
from calibctl.store.images import ImageStoreMixin
from calibctl.store.models import ArtifactRow, Base, BoardRow, EventRow, ImageRow, SessionRow
from calibctl.store.rigs import RigStoreMixin, rig_member_session_ids

if TYPE_CHECKING:
    from calibctl.store import audit

T = TypeVar("T")
R = TypeVar("R", bound=Base)
MAX_ATTEMPTS = 5
_GEOMETRY = ("kind", "cols", "rows", "marker_size_m", "dictionary", "inverted", "legacy_pattern")


def _no_store(url: str, status: str, path: Path | None) -> NotFoundError:
    """A read of a store that does not exist: name what was looked for, never create it by looking."""
    what = (
        f"{path.resolve()} does not exist"
        if status == "absent" and path is not None
        else "it has no calibctl tables"
    )
    return NotFoundError(
        f"there is no calibctl database at {url} ({what})",
        "check --db / CALIBCTL_DB for a typo; a new store is created by `calibctl db upgrade` "
        "(or by `calibctl board add`, `capture` or `import`)",
    )


class Store(ImageStoreMixin, RigStoreMixin, CheckStoreMixin, FleetStoreMixin, HealthStoreMixin):
    """A calibctl store on SQLite or PostgreSQL. Open it with ``Store.open(url)``."""

    def __init__(
        self,
        engine: Engine,
        image_dir: Path,
        signer: Signer | None = None,
        trusted: TrustedKeys | None = None,
    ) -> None:
        self._engine = engine
        self.signer = signer
        self.trusted = trusted
        self._write_engine = engine.execution_options(**{WRITE_OPTION: True})
        self.image_dir = image_dir

    @classmethod
    def open(
        cls,
        url: str,
        *,
        create: bool = True,
        image_dir: Path | None = None,
        signer: Signer | None = None,
        trusted: TrustedKeys | None = None,
    ) -> Store:
        """Open the store at ``url``. A new (absent or empty) database is created at the newest schema
        revision when ``create``; an older revision is refused with DatabaseOutOfDateError. With a
        ``signer`` every board revision, artifact and event written is signed. With ``trusted`` (keys
        configured), every artifact, rig version and activation event a read serves is checked as
        ``db verify`` would check it (``served``: its link and signature) and refused when flagged."""
        engine = _make_engine(url)
        try:
            state = migrate.read_state(engine)
            if state.status in ("absent", "empty"):
                if not create:
                    raise _no_store(state.url, state.status, sqlite_path(engine.url))
                migrate.upgrade(engine)
                state = migrate.read_state(engine)
            state.require_current()
        except BaseException:
            engine.dispose()
            raise
        return cls(engine, image_dir or images.default_image_dir(engine.url), signer, trusted)

    @property
    def url(self) -> str:
        """The database URL with the password hidden."""
        return display_url(self._engine.url)

    @property
    def backend(self) -> str:
        return self._engine.dialect.name

    def close(self) -> None:
        self._engine.dispose()

    def __enter__(self) -> Store:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _run(self, work: Callable[[Session], T], *, write: bool = False, retry_conflicts: bool = False) -> T:
        """Run ``work`` in one transaction; retry (bounded) on serialization failures and, when asked,
        on unique-key conflicts with a concurrent writer (the retry then sees the committed row)."""
        for attempt in range(1, MAX_ATTEMPTS + 1):
            try:
                engine = self._write_engine if write else self._engine
                with Session(engine, expire_on_commit=False) as session, session.begin():
                    return work(session)
            except sa_exc.DBAPIError as exc:
                retry = is_retryable(exc) or (retry_conflicts and is_unique_violation(exc))
                if retry and attempt < MAX_ATTEMPTS:
                    continue
                mapped = as_database_error(exc, self._engine)
                if mapped is None:
                    raise
                raise mapped from exc
        raise DatabaseError(f"the database {self.url} kept refusing the transaction")  # pragma: no cover

    def _served(self, s: Session, stream: str, row: Base | None) -> None:
        """With keys configured, refuse ``row`` (a record a read serves) if ``db verify`` would flag it."""
        if row is not None and self.trusted is not None:
            served.check(
                stream,
                row,
                lambda sql, params: [dict(r) for r in s.execute(text(sql), params).mappings()],
                self.trusted,
            )

    def _linked(self, stream: str, s: Session, row: R) -> R:
        """``row`` with its chain (and, with a key, signature) columns set; the caller holds the stream's lock."""
        chain.link(s, chain.STREAMS[stream], row, self.signer)
        return row

    # boards --------------------------------------------------------------------------------------

    def add_board(self, board: BoardRevision) -> BoardRevision:
        """Store the next revision of ``board.name`` (``board.revision`` is ignored); returns the stored copy.
        A new revision re-measures the same pattern: kind, size and markers must not change."""

        def work(s: Session) -> BoardRevision:
            revision = counters.next_value(s, "board", board.name)
            latest = s.scalars(
                select(BoardRow)
                .where(BoardRow.name == board.name)
                .order_by(BoardRow.revision.desc())
                .limit(1)
            ).first()
            if latest is not None:
                previous = codec.decode_board(latest)
                changed = [f for f in _GEOMETRY if getattr(previous, f) != getattr(board, f)]
                if changed:
                    raise UsageError(
                        f"board {previous.ref} is a {previous.cols}x{previous.rows} {previous.kind}; a new revision "
                        f"may only re-measure it, but {', '.join(changed)} differ",
                        "register a different pattern under a new name",
                    )
            stored = board.model_copy(update={"revision": revision})
            s.add(self._linked("board", s, codec.board_row(stored)))
            s.flush()
            return stored

        return self._run(work, write=True)

    def get_board(self, name: str, revision: int | None = None) -> BoardRevision:
        """Revision ``revision`` of board ``name`` (None: the latest)."""

        def work(s: Session) -> BoardRevision:
            revisions = list(
                s.scalars(select(BoardRow.revision).where(BoardRow.name == name).order_by(BoardRow.revision))
            )
            if not revisions:
                names = list(s.scalars(select(BoardRow.name).distinct().order_by(BoardRow.name)))
                if not names:
                    raise NotFoundError(
                        f"unknown board '{name}'; no boards are registered yet",
                        "add one with `calibctl board add`",
                    )
                raise NotFoundError(
                    f"unknown board '{name}'; known: {named_list(names, history.KNOWN_SHOWN)}",
                    "see `calibctl board list`",
                )
            wanted = revisions[-1] if revision is None else revision
            if wanted not in revisions:
                raise NotFoundError(
                    f"board {name} has no revision {revision}; revisions: {named_list(revisions, history.KNOWN_SHOWN)}",
                    f"see `calibctl board show {name}`",
                )
            row = s.scalars(select(BoardRow).where(BoardRow.name == name, BoardRow.revision == wanted)).one()
            return codec.decode_board(row)

        return self._run(work)

    def board_revisions(self, name: str) -> list[int]:
        """The revision numbers of board ``name`` (empty when it is unknown)."""
        return self._run(
            lambda s: list(
                s.scalars(select(BoardRow.revision).where(BoardRow.name == name).order_by(BoardRow.revision))
            )
        )

    def list_boards(self) -> list[BoardRevision]:
        """Every revision of every board, by name then revision."""
        return self._run(
            lambda s: [
                codec.decode_board(r)
                for r in s.scalars(select(BoardRow).order_by(BoardRow.name, BoardRow.revision))
            ]
        )

    # capture sessions ----------------------------------------------------------------------------

    def add_session(self, session: CaptureSession) -> None:
        """Store a capture session; its id must be new (sessions are immutable)."""

        def work(s: Session) -> None:
            if s.get(SessionRow, session.session_id) is not None:
                raise AlreadyExistsError(f"capture session {session.session_id} is already stored")
            s.add(self._session_linked(s, codec.session_row(session)))
            s.flush()

        self._run(work, write=True, retry_conflicts=True)

    def _session_linked(self, s: Session, row: SessionRow) -> SessionRow:
        """``row`` numbered and chained in its serial's session stream (revision 0009), under that stream's lock
        (the ('session', serial) counter row). Its id comes from the store-wide ('id', 'capture_sessions')
        counter, whose row is held only for this one insert (so stations capturing different cameras wait
        milliseconds, never retry); a counter behind the stored ids (a store chained by 0009) catches up."""
        counters.next_value(s, "session", row.serial)
        candidate = counters.next_value(s, "id", "capture_sessions")
        highest = int(s.scalar(select(func.max(SessionRow.id))) or 0)
        row.id = (
            candidate if candidate > highest else counters.raise_to(s, "id", "capture_sessions", highest + 1)
        )
        return self._linked("session", s, row)

    def get_session(self, session_id: str) -> CaptureSession:
        def work(s: Session) -> CaptureSession:
            row = s.get(SessionRow, session_id)
            if row is None:
                recent = list(
                    s.scalars(select(SessionRow.session_id).order_by(SessionRow.started_at.desc()).limit(10))
                )
                listing = (
                    f"recent: {named_list(recent, history.KNOWN_SHOWN)}"
                    if recent
                    else "no sessions are stored yet"
                )
                raise NotFoundError(
                    f"unknown capture session '{session_id}'; {listing}", "run `calibctl capture`"
                )
            session = codec.decode_session(row)
            self._served(s, "session", row)
            return session

        return self._run(work)

    def latest_session(self, serial: str, status: str | None = "accepted") -> CaptureSession:
        """The most recent session of ``serial`` (with ``status``, unless None). Sessions taken as members
        of a rig capture are never picked here: a single-camera solve uses them only when named."""

        def work(s: Session) -> CaptureSession:
            members = rig_member_session_ids(s)
            query = select(SessionRow).where(SessionRow.serial == serial)
            if members:
                query = query.where(SessionRow.session_id.not_in(members))
            if status is not None:
                query = query.where(SessionRow.status == status)
            row = s.scalars(
                query.order_by(SessionRow.finished_at.desc(), SessionRow.started_at.desc()).limit(1)
            ).first()
            if row is not None:
                return codec.decode_session(row)
            theirs = s.execute(
                select(SessionRow.session_id, SessionRow.status)
                .where(SessionRow.serial == serial)
                .order_by(SessionRow.started_at)
            ).all()
            what = f"no {status} capture session" if status else "no capture session"
            if theirs:
                listing = named_list(
                    [f"{sid} ({st}{', rig member' if sid in members else ''})" for sid, st in theirs],
                    history.KNOWN_SHOWN,
                )
                hint = (
                    "capture again, or name a rig member's session: calibctl solve SESSION_ID"
                    if any(sid in members for sid, _ in theirs)
                    else "capture again"
                )
                raise NotFoundError(f"{what} for serial '{serial}'; its sessions: {listing}", hint)
            serials = list(s.scalars(select(SessionRow.serial).distinct().order_by(SessionRow.serial)))
            listing = (
                f"serials with sessions: {named_list(serials, history.KNOWN_SHOWN)}"
                if serials
                else "no sessions are stored yet"
            )
            raise NotFoundError(f"{what} for serial '{serial}'; {listing}", "run `calibctl capture` first")

        return self._run(work)

    def list_sessions(self, serial: str | None = None) -> list[CaptureSession]:
        def work(s: Session) -> list[CaptureSession]:
            query = select(SessionRow).order_by(SessionRow.started_at, SessionRow.session_id)
            if serial is not None:
                query = query.where(SessionRow.serial == serial)
            return [codec.decode_session(r) for r in s.scalars(query)]

        return self._run(work)

    # calibration artifacts -----------------------------------------------------------------------

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
        history.check_activation(artifact, activate, reason)
        return self._run(
            lambda s: self._insert_artifact(s, artifact, activate, actor, station, reason, expect_version),
            write=True,
        )

    def add_artifact_once(
        self, artifact: CalibrationArtifact, *, activate: bool, actor: str, station: str, reason: str
    ) -> tuple[CalibrationArtifact, bool]:
        """``add_artifact`` unless the serial already has a calibration solved from the same capture session
        (``provenance.session_id``): then that one, and False. The look and the insert are one transaction
        under the serial's version lock, so a sync run again after a crash never stores a calibration twice."""
        history.check_activation(artifact, activate, reason)

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

        return self._run(work, write=True)

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
        version = counters.next_value(s, "artifact", artifact.serial)
        if expect_version is not None and version != expect_version:
            raise UsageError(
                f"{artifact.serial}@{expect_version} cannot be stored: this store's next version "
                f"of {artifact.serial} is {version} (another was stored meanwhile); nothing was "
                "written",
                "run the command again",
            )
        stored = artifact.model_copy(update={"version": version}).sealed()
        s.add(self._linked("artifact", s, codec.artifact_row(stored, utc_now())))
        s.flush()
        if activate:
            history.append_event(s, artifact.serial, version, "activate", actor, station, reason, self.signer)
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
        history.check_activation(artifact, activate, why)

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
                        f"{artifact.ref} already exists in {self.url} with different content (stored sha256 "
                        f"{row.content_sha256[:12]}, imported {artifact.content_sha256[:12]})",
                        "versions are immutable: this store's history for that serial differs from the file's",
                    )
                stored = codec.decode_artifact(row)
            else:
                s.add(self._linked("artifact", s, codec.artifact_row(artifact, utc_now())))
                s.flush()
                stored = artifact
            if activate and history.active_in(s, artifact.serial) != artifact.version:
                history.append_event(
                    s, artifact.serial, artifact.version, "activate", actor, station, why, self.signer
                )
            return stored

        return self._run(work, write=True, retry_conflicts=True)

    def get_artifact(self, serial: str, version: int | None = None) -> CalibrationArtifact:
        """``serial@version``; None means the active version. Its record is checked by its chain hash
        (IntegrityError): one sha256 over the stored bytes and columns, content_sha256 included, which a
        writer without the chain cannot change unseen; ``db verify`` and import re-derive content hashes."""

        def work(s: Session) -> CalibrationArtifact:
            statuses = history.statuses(s, serial)
            if version is None:
                wanted = history.active_in(s, serial)
                if wanted is None:
                    listing = named_list([f"{v} ({st})" for v, st in statuses.items()], history.KNOWN_SHOWN)
                    raise NotFoundError(
                        f"{serial} has no active version; versions: {listing}",
                        f"ask for a version ({serial}@N) or roll back to an accepted one"
                        if "accepted" in statuses.values()
                        else f"none is accepted: recalibrate it (`calibctl calibrate --serial {serial} ...`), or ask for "
                        f"a version ({serial}@N) to inspect it",
                    )
                if statuses.get(wanted) != "accepted":  # only possible if the event log was forged
                    raise IntegrityError(
                        f"the active version of {serial} is {serial}@{wanted}, which is not accepted: "
                        "the activation log was changed outside calibctl",
                        codec.TAMPER_HINT,
                    )
            elif version not in statuses:
                raise NotFoundError(
                    f"{serial} has no version {version}; versions: {named_list(list(statuses), history.KNOWN_SHOWN)}",
                    f"see `calibctl history {serial}`",
                )
            else:
                wanted = version
            row = history.artifact_row(s, serial, wanted)
            art = codec.decode_artifact(row, by_chain=True)
            self._served(s, "artifact", row)
            if version is None:  # the event that makes it active is served too
                self._served(s, "event", history.active_event(s, serial))
            return art

        return self._run(work)

    def list_artifacts(self, serial: str) -> list[CalibrationArtifact]:
        """Every version of ``serial``, oldest first (each checked by its chain hash, as ``get_artifact``)."""

        def work(s: Session) -> list[CalibrationArtifact]:
            history.statuses(s, serial)
            rows = s.scalars(
                select(ArtifactRow).where(ArtifactRow.serial == serial).order_by(ArtifactRow.version)
            )
            return [codec.decode_artifact(r, by_chain=True) for r in rows]

        return self._run(work)

    def active_artifacts(
        self,
    ) -> tuple[dict[str, CalibrationArtifact | IntegrityError], dict[str, dict[int, str]]]:
        """The active version of every serial in three bulk queries (no per-serial round trip), each checked
        by its chain hash (an IntegrityError in its place when that fails), and version -> status of
        every serial with nothing active."""

        def work(
            s: Session,
        ) -> tuple[dict[str, CalibrationArtifact | IntegrityError], dict[str, dict[int, str]]]:
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
            found: dict[str, CalibrationArtifact | IntegrityError] = {}
            events = (
                {}
                if self.trusted is None
                else {
                    e.serial: e for e in s.scalars(select(EventRow).join(latest, EventRow.id == latest.c.id))
                }
            )
            for row in rows:
                try:
                    art = codec.decode_artifact(row, by_chain=True)
                    self._served(s, "artifact", row)
                    self._served(s, "event", events.get(row.serial))
                    if art.status != "accepted":
                        raise IntegrityError(
                            f"the active version of {art.serial} is {art.ref}, which is not accepted: "
                            "the activation log was changed outside calibctl",
                            codec.TAMPER_HINT,
                        )
                    found[row.serial] = art
                except IntegrityError as exc:
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

        return self._run(work)

    def serials(self) -> list[str]:
        return self._run(
            lambda s: list(s.scalars(select(ArtifactRow.serial).distinct().order_by(ArtifactRow.serial)))
        )

    def active_version(self, serial: str) -> int | None:
        """The version of the serial's latest activation event; None when nothing was ever activated."""
        return self._run(lambda s: history.active_in(s, serial))

    def next_version(self, serial: str) -> int:
        """The version the next artifact of ``serial`` would get (nothing is allocated)."""
        return self._run(lambda s: (counters.peek(s, "artifact", serial) or 0) + 1)

    def rollback(
        self,
        serial: str,
        to_version: int,
        *,
        reason: str,
        actor: str,
        station: str,
        expected_active: int | None | object = history.UNCHECKED,
    ) -> ActivationEvent | None:
        """Make ``to_version`` (accepted, intact) the active version of ``serial``; appends an event.
        None when it is the active version already: done, nothing written.

        Compare-and-set: ``expected_active`` is the active version the caller decided on (None: nothing
        was active); when another writer moved it since, nothing is written (StaleActiveVersionError)."""
        if not reason.strip():
            raise UsageError("a rollback needs a reason", "pass --reason 'why this version'")

        def work(s: Session) -> ActivationEvent | None:
            counters.lock(s, "artifact", serial)
            already = history.check_rollback(
                serial,
                to_version,
                history.statuses(s, serial),
                history.active_in(s, serial),
                expected_active,
                f"calibctl history {serial}",
            )
            codec.decode_artifact(
                history.artifact_row(s, serial, to_version), by_chain=True
            )  # never activate tampered bytes
            if already:
                return None
            return history.append_event(
                s, serial, to_version, "rollback", actor, station, reason, self.signer
            )

        return self._run(work, write=True)

    def events(self, serial: str) -> list[ActivationEvent]:
        """The serial's activation events, oldest first."""
        return self._run(
            lambda s: [
                codec.decode_event(r)
                for r in s.scalars(select(EventRow).where(EventRow.serial == serial).order_by(EventRow.id))
            ]
        )

    # audit ---------------------------------------------------------------------------------------

    def counts(self) -> dict[str, int]:
        def work(s: Session) -> dict[str, int]:
            tables = {
                "artifacts": ArtifactRow,
                "boards": BoardRow,
                "sessions": SessionRow,
                "events": EventRow,
                "images": ImageRow,
            }
            result = {
                name: int(s.scalar(select(func.count()).select_from(model)) or 0)
                for name, model in tables.items()
            }
            result["serials"] = int(s.scalar(select(func.count(ArtifactRow.serial.distinct()))) or 0)
            return result

        return self._run(work)

    def verify(
        self, trusted: TrustedKeys | None = None, *, require_signature: bool = False, since: str | None = None
    ) -> audit.Audit:
        """Every chain, signature, counter, event and stored hash (see ``store.audit``); with ``since``
        (a chain head) only what was written after it, once the head is proven unchanged."""
        from calibctl.store import audit  # the whole-store audit: only `db verify` and its callers

        return self._run(
            lambda s: audit.run(s, trusted or TrustedKeys(), require_signature=require_signature, since=since)
        )
