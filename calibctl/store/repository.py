"""The Store: one object callers open, made of parts that share one ``runner.Runner``.

Boards and capture sessions live here; camera artifacts (``cameras``), rigs, images, checks, the fleet log
and health reports are parts the Store offers under their own method names. Every public method is one
transaction and returns contract documents (pydantic), never ORM rows. Every read of a document re-checks
its hash (UnverifiedRecord naming it on mismatch): a calibration by its record's chain hash (covering its
bytes and content_sha256), the others by their sha256. The active version of a serial or rig is not a
mutable pointer: it is the version of its latest activation event (``history``), and events are
append-only (database triggers refuse UPDATE/DELETE).
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.session import CaptureSession
from calibctl.errors import AlreadyExistsError, NotFoundError, UsageError, named_list
from calibctl.signing import Signer, TrustedKeys
from calibctl.store import codec, counters, images, migrate
from calibctl.store.cameras import CameraStore
from calibctl.store.checks import CheckStore
from calibctl.store.engine import display_url, sqlite_path
from calibctl.store.engine import make_engine as _make_engine
from calibctl.store.fleet import FleetStore
from calibctl.store.gauge_failures import GaugeFailureStore
from calibctl.store.health import HealthStore
from calibctl.store.history import KNOWN_SHOWN
from calibctl.store.images import ImageStore
from calibctl.store.models import ArtifactRow, BoardRow, EventRow, ImageRow, SessionRow
from calibctl.store.rigs import RigStore, rig_member_session_ids
from calibctl.store.runner import Delegate, Runner

if TYPE_CHECKING:
    from calibctl.store import audit

_GEOMETRY = (
    "kind", "cols", "rows", "marker_size_m", "dictionary", "inverted", "legacy_pattern", "tag_spacing"
)  # fmt: skip


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


class Store:
    """A calibctl store on SQLite or PostgreSQL. Open it with ``Store.open(url)``.

    Built from parts that share one ``Runner`` (the engine, transactions, signing and checking keys):
    boards and capture sessions are here; cameras' artifacts, rigs, images, checks, the fleet log and
    health reports are parts, whose methods the Store offers under the same names (``Delegate``)."""

    def __init__(
        self,
        engine: Engine,
        image_dir: Path,
        signer: Signer | None = None,
        trusted: TrustedKeys | None = None,
    ) -> None:
        self._runner = Runner(engine, signer, trusted)
        self._engine, self._write_engine = self._runner.engine, self._runner.write_engine  # tests, benchmarks
        self.signer, self.trusted, self.image_dir = (
            signer,
            trusted,
            image_dir,
        )  # as opened; the parts hold them
        self._cameras = CameraStore(self._runner)
        self._rigs = RigStore(self._runner, self._session_linked)
        self._images = ImageStore(self._runner, image_dir)
        self._checks = CheckStore(self._runner)
        self._gauges = GaugeFailureStore(self._runner)
        self._fleet = FleetStore(self._runner)
        self._health = HealthStore(self._runner)

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
                previous = codec.decode_board(latest, by_chain=True)
                changed = [f for f in _GEOMETRY if getattr(previous, f) != getattr(board, f)]
                if changed:
                    raise UsageError(
                        f"board {previous.ref} is a {previous.cols}x{previous.rows} {previous.kind}; a new "
                        f"revision may only re-measure it, but {', '.join(changed)} differ",
                        "register a different pattern under a new name",
                    )
            stored = board.model_copy(update={"revision": revision})
            s.add(self._runner.linked("board", s, codec.board_row(stored)))
            s.flush()
            return stored

        return self._runner.run(work, write=True)

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
                    f"unknown board '{name}'; known: {named_list(names, KNOWN_SHOWN)}",
                    "see `calibctl board list`",
                )
            wanted = revisions[-1] if revision is None else revision
            if wanted not in revisions:
                raise NotFoundError(
                    f"board {name} has no revision {revision}; revisions: "
                    f"{named_list(revisions, KNOWN_SHOWN)}",
                    f"see `calibctl board show {name}`",
                )
            row = s.scalars(select(BoardRow).where(BoardRow.name == name, BoardRow.revision == wanted)).one()
            board = codec.decode_board(row, by_chain=True)
            self._runner.served(s, "board", row)
            return board

        return self._runner.run(work)

    def board_revisions(self, name: str) -> list[int]:
        """The revision numbers of board ``name`` (empty when it is unknown)."""
        return self._runner.run(
            lambda s: list(
                s.scalars(select(BoardRow.revision).where(BoardRow.name == name).order_by(BoardRow.revision))
            )
        )

    def list_boards(self) -> list[BoardRevision]:
        """Every revision of every board, by name then revision, each checked as ``get_board`` checks it."""

        def work(s: Session) -> list[BoardRevision]:
            boards = []
            for row in s.scalars(select(BoardRow).order_by(BoardRow.name, BoardRow.revision)):
                boards.append(codec.decode_board(row, by_chain=True))
                self._runner.served(s, "board", row)
            return boards

        return self._runner.run(work)

    # capture sessions ----------------------------------------------------------------------------

    def add_session(self, session: CaptureSession) -> None:
        """Store a capture session; its id must be new (sessions are immutable)."""

        def work(s: Session) -> None:
            if s.get(SessionRow, session.session_id) is not None:
                raise AlreadyExistsError(f"capture session {session.session_id} is already stored")
            s.add(self._session_linked(s, codec.session_row(session)))
            s.flush()

        self._runner.run(work, write=True, retry_conflicts=True)

    def _session_linked(self, s: Session, row: SessionRow) -> SessionRow:
        """``row`` numbered and chained in its serial's session stream (revision 0009), under that stream's
        lock (the ('session', serial) counter row). Its id comes from the store-wide
        ('id', 'capture_sessions') counter, whose row is held only for this one insert (so stations capturing
        different cameras wait milliseconds, never retry); a counter behind the stored ids (a store chained by
        0009) catches up."""
        counters.next_value(s, "session", row.serial)
        candidate = counters.next_value(s, "id", "capture_sessions")
        highest = int(s.scalar(select(func.max(SessionRow.id))) or 0)
        row.id = (
            candidate if candidate > highest else counters.raise_to(s, "id", "capture_sessions", highest + 1)
        )
        return self._runner.linked("session", s, row)

    def get_session(self, session_id: str) -> CaptureSession:
        def work(s: Session) -> CaptureSession:
            row = s.get(SessionRow, session_id)
            if row is None:
                recent = list(
                    s.scalars(select(SessionRow.session_id).order_by(SessionRow.started_at.desc()).limit(10))
                )
                listing = (
                    f"recent: {named_list(recent, KNOWN_SHOWN)}" if recent else "no sessions are stored yet"
                )
                raise NotFoundError(
                    f"unknown capture session '{session_id}'; {listing}", "run `calibctl capture`"
                )
            session = codec.decode_session(row)
            self._runner.served(s, "session", row)
            return session

        return self._runner.run(work)

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
                    KNOWN_SHOWN,
                )
                hint = (
                    "capture again, or name a rig member's session: calibctl solve SESSION_ID"
                    if any(sid in members for sid, _ in theirs)
                    else "capture again"
                )
                raise NotFoundError(f"{what} for serial '{serial}'; its sessions: {listing}", hint)
            serials = list(s.scalars(select(SessionRow.serial).distinct().order_by(SessionRow.serial)))
            listing = (
                f"serials with sessions: {named_list(serials, KNOWN_SHOWN)}"
                if serials
                else "no sessions are stored yet"
            )
            raise NotFoundError(f"{what} for serial '{serial}'; {listing}", "run `calibctl capture` first")

        return self._runner.run(work)

    def list_sessions(self, serial: str | None = None) -> list[CaptureSession]:
        def work(s: Session) -> list[CaptureSession]:
            query = select(SessionRow).order_by(SessionRow.started_at, SessionRow.session_id)
            if serial is not None:
                query = query.where(SessionRow.serial == serial)
            return [codec.decode_session(r) for r in s.scalars(query)]

        return self._runner.run(work)

    # the parts' methods ---------------------------------------------------------------------------

    add_artifact = Delegate("_cameras", CameraStore.add_artifact)
    add_artifact_once = Delegate("_cameras", CameraStore.add_artifact_once)
    import_artifact = Delegate("_cameras", CameraStore.import_artifact)
    get_artifact = Delegate("_cameras", CameraStore.get_artifact)
    list_artifacts = Delegate("_cameras", CameraStore.list_artifacts)
    active_artifacts = Delegate("_cameras", CameraStore.active_artifacts)
    serials = Delegate("_cameras", CameraStore.serials)
    active_version = Delegate("_cameras", CameraStore.active_version)
    next_version = Delegate("_cameras", CameraStore.next_version)
    rollback = Delegate("_cameras", CameraStore.rollback)
    events = Delegate("_cameras", CameraStore.events)

    add_rig = Delegate("_rigs", RigStore.add_rig)
    get_rig = Delegate("_rigs", RigStore.get_rig)
    add_rig_session = Delegate("_rigs", RigStore.add_rig_session)
    get_rig_session = Delegate("_rigs", RigStore.get_rig_session)
    add_rig_calibration = Delegate("_rigs", RigStore.add_rig_calibration)
    get_rig_calibration = Delegate("_rigs", RigStore.get_rig_calibration)
    list_rig_calibrations = Delegate("_rigs", RigStore.list_rig_calibrations)
    active_rig_version = Delegate("_rigs", RigStore.active_rig_version)
    rollback_rig = Delegate("_rigs", RigStore.rollback_rig)
    rig_events = Delegate("_rigs", RigStore.rig_events)

    put_image = Delegate("_images", ImageStore.put_image)
    put_images = Delegate("_images", ImageStore.put_images)
    image_path = Delegate("_images", ImageStore.image_path)
    orphan_images = Delegate("_images", ImageStore.orphan_images)
    prune_images = Delegate("_images", ImageStore.prune_images)

    add_check = Delegate("_checks", CheckStore.add_check)
    checks = Delegate("_checks", CheckStore.checks)
    checks_since = Delegate("_checks", CheckStore.checks_since)

    failed_gauges = Delegate("_gauges", GaugeFailureStore.failed_gauges)

    add_fleet_event = Delegate("_fleet", FleetStore.add_fleet_event)
    append_fleet_events = Delegate("_fleet", FleetStore.append_fleet_events)
    active_versions = Delegate("_fleet", FleetStore.active_versions)
    fleet = Delegate("_fleet", FleetStore.fleet)
    fleet_events = Delegate("_fleet", FleetStore.fleet_events)

    add_health_reports = Delegate("_health", HealthStore.add_health_reports)
    health_rows = Delegate("_health", HealthStore.health_rows)
    fleet_check_rms = Delegate("_health", HealthStore.fleet_check_rms)
    gate_reports = Delegate("_health", HealthStore.gate_reports)
    health_report_count = Delegate("_health", HealthStore.health_report_count)

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

        return self._runner.run(work)

    def verify(
        self, trusted: TrustedKeys | None = None, *, require_signature: bool = False, since: str | None = None
    ) -> audit.Audit:
        """Every chain, signature, counter, event and stored hash (see ``store.audit``); with ``since``
        (a chain head) only what was written after it, once the head is proven unchanged."""
        from calibctl.store import audit  # the whole-store audit: only `db verify` and its callers

        return self._runner.run(
            lambda s: audit.run(s, trusted or TrustedKeys(), require_signature=require_signature, since=since)
        )
