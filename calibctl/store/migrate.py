"""Schema revisions: where a database stands, and programmatic alembic upgrade/downgrade.

The migration scripts live in the top-level ``migrations/`` directory (next to ``alembic.ini``); a
wheel ships them as ``calibctl/_migrations`` (pyproject's package-dir), which is looked for first.
Every migration runs inside one write transaction that also holds a migration lock (SQLite:
``BEGIN IMMEDIATE``; PostgreSQL: a transaction-scoped advisory lock), so two stations opening a
brand-new shared store at the same moment create it exactly once, and a failed migration leaves the
database at its previous revision.
"""

from __future__ import annotations

import ast
import contextlib
import functools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from calibctl.errors import DatabaseError, DatabaseOutOfDateError

if TYPE_CHECKING:
    from alembic.config import Config
    from alembic.script import ScriptDirectory
    from sqlalchemy import Connection, Engine

# sqlalchemy (through calibctl.store.engine and .models) is imported by the functions that connect:
# head_revision() is also what the sqlite3 read path (calibctl.store.sqlite_reads) checks a store against.

PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def migrations_dir(package_root: Path = PACKAGE_ROOT) -> Path:
    """``calibctl/_migrations`` in an installed wheel, the checkout's ``migrations/`` otherwise."""
    packaged = package_root / "_migrations"
    return packaged if (packaged / "env.py").is_file() else package_root.parent / "migrations"


MIGRATIONS_DIR = migrations_dir()
ALEMBIC_INI = MIGRATIONS_DIR.parent / "alembic.ini"  # a checkout's; a wheel needs none of its settings
_MIGRATION_LOCK_KEY = 0x63616C6962  # "calib": pg_advisory_xact_lock key for migrations

SchemaStatus = Literal["absent", "empty", "current", "out_of_date", "unknown"]


def alembic_config(connection: Connection | None = None) -> Config:
    """An alembic Config for calibctl's migrations; ``connection`` is used instead of a URL when given."""
    from alembic.config import Config

    cfg = Config(str(ALEMBIC_INI)) if ALEMBIC_INI.exists() else Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    if connection is not None:
        cfg.attributes["connection"] = connection
    return cfg


def script_directory() -> ScriptDirectory:
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(alembic_config())


# Every command checks the schema revision, but only `db upgrade` and a brand-new store migrate.
# Reading the revision ids from the migration files and the database directly keeps alembic (and
# mako, pygments) out of every other command's start-up; tests compare this with alembic's answer.
_REVISION_LINE = re.compile(r"^(revision|down_revision)\b[^=\n]*=\s*(.+?)\s*$", re.MULTILINE)


@functools.cache
def _revision_graph() -> dict[str, tuple[str, ...]]:
    """revision -> the revisions it follows, read from ``MIGRATIONS_DIR/versions/*.py``."""
    graph: dict[str, tuple[str, ...]] = {}
    for path in sorted((MIGRATIONS_DIR / "versions").glob("*.py")):
        fields = dict(_REVISION_LINE.findall(path.read_text(encoding="utf-8")))
        down = ast.literal_eval(fields.get("down_revision", "None"))
        downs = () if down is None else (down,) if isinstance(down, str) else tuple(down)
        graph[ast.literal_eval(fields["revision"])] = downs
    return graph


def head_revision() -> str:
    graph = _revision_graph()
    heads = sorted(set(graph) - {d for downs in graph.values() for d in downs})
    if len(heads) != 1:  # pragma: no cover - the repository always has exactly one head
        raise DatabaseError(
            f"{len(heads)} migration heads in {MIGRATIONS_DIR} ({', '.join(heads)}); expected one"
        )
    return heads[0]


def known_revisions() -> list[str]:
    """Every revision this calibctl knows, oldest first."""
    graph, ordered = _revision_graph(), []

    def visit(rev: str) -> None:
        if rev not in ordered:
            for down in graph[rev]:
                visit(down)
            ordered.append(rev)

    visit(head_revision())
    return ordered


@dataclass(frozen=True)
class SchemaState:
    """Where a database stands relative to this calibctl's migrations."""

    url: str
    current: str | None
    head: str
    status: SchemaStatus

    def require_current(self) -> None:
        """Raise unless the database is at head (absent/empty databases are the caller's business)."""
        if self.status == "out_of_date":
            raise DatabaseOutOfDateError(
                f"the database {self.url} is at revision {self.current}, this calibctl needs {self.head}",
                "run `calibctl db upgrade` (it migrates the database and keeps its data)",
            )
        if self.status == "unknown":
            raise DatabaseError(
                f"the database {self.url} is at revision {self.current}, which this calibctl does not know "
                f"(its newest is {self.head}); a newer calibctl migrated it",
                "upgrade calibctl on this station",
            )


def _current_revision(conn: Connection, tables: set[str] | None = None) -> str | None:
    """The revision in alembic's version table (None when there is none). ``tables``: the database's
    tables when the caller has just listed them (no second look for the version table)."""
    from sqlalchemy import inspect, text

    listed = tables is not None and "alembic_version" in tables
    if not (listed if tables is not None else inspect(conn).has_table("alembic_version")):
        return None
    rows = conn.execute(text("SELECT version_num FROM alembic_version")).scalars().all()
    if len(rows) > 1:
        raise DatabaseError(
            f"the database is at several schema revisions at once ({', '.join(rows)})",
            "it was migrated by something other than calibctl; restore it from a backup",
        )
    return rows[0] if rows else None


def refuse_foreign(tables: set[str], url: str, revision: str | None) -> None:
    """DatabaseError naming the database when it holds tables that are not calibctl's: another
    application's database is never written into (not a table added, not a byte changed). A store at one
    of calibctl's own revisions (``revision``) may hold a table an older revision made: its own."""
    from calibctl.store.models import Base

    if revision is not None and revision in known_revisions():
        return
    foreign = sorted(t for t in tables if t not in Base.metadata.tables and t != "alembic_version")
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise DatabaseError(
            f"the database {url} is not a calibctl store: it holds tables calibctl did not make ({shown}); "
            "nothing was written to it",
            "point --db (CALIBCTL_DB) at a calibctl store, or at a new file or empty database for a new one",
        )


def _sqlite_tables(path: Path) -> tuple[set[str], str | None]:
    """The tables of an existing SQLite file and its alembic revision, read without writing a byte
    (``immutable=1``: no journal mode set, no -wal or -shm made). A file that is no SQLite database is
    refused naming it."""
    import sqlite3
    import urllib.parse

    uri = f"file:{urllib.parse.quote(str(path.resolve()))}?mode=ro&immutable=1"
    try:
        with contextlib.closing(sqlite3.connect(uri, uri=True)) as conn:
            rows = conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()
            tables = {str(r[0]) for r in rows if not str(r[0]).startswith("sqlite_")}
            revisions = (
                conn.execute("SELECT version_num FROM alembic_version").fetchall()
                if "alembic_version" in tables
                else []
            )
    except sqlite3.DatabaseError as exc:
        raise DatabaseError(
            f"{path} is not a SQLite database ({exc}); nothing was written to it",
            "point --db (CALIBCTL_DB) at a calibctl store, or at a path that does not exist yet (a new one)",
        ) from exc
    return tables, str(revisions[0][0]) if len(revisions) == 1 else None


def _refuse_foreign_file(path: Path | None) -> None:
    """An existing SQLite file with another application's tables (or no database at all) is refused before
    any connection opens it: a connection sets the WAL journal mode, which rewrites the file's header."""
    if path is not None and path.is_file() and path.stat().st_size > 0:
        tables, revision = _sqlite_tables(path)
        refuse_foreign(tables, str(path), revision)


def _state_on(conn: Connection, url: str) -> SchemaState:
    from sqlalchemy import inspect

    from calibctl.store.models import Base

    head = head_revision()
    tables = set(inspect(conn).get_table_names())
    current = _current_revision(conn, tables)  # read once: the foreign-table check and the state share it
    refuse_foreign(tables, url, current)
    if current is None:
        ours = tables & set(Base.metadata.tables)
        if ours:
            raise DatabaseError(
                f"the database {url} has calibctl tables ({', '.join(sorted(ours))}) but no schema revision",
                "it was not created by calibctl; point --db at a calibctl store or an empty database",
            )
        return SchemaState(url, None, head, "empty")
    if current == head:
        return SchemaState(url, current, head, "current")
    status: SchemaStatus = "out_of_date" if current in known_revisions() else "unknown"
    return SchemaState(url, current, head, status)


def read_state(engine: Engine) -> SchemaState:
    """The schema state of ``engine``'s database. A SQLite file that does not exist is ``absent``
    (and is not created by looking at it)."""
    from calibctl.store.engine import database_errors, display_url, sqlite_path

    url = display_url(engine.url)
    path = sqlite_path(engine.url)
    if path is not None and not path.exists():
        return SchemaState(url, None, head_revision(), "absent")
    _refuse_foreign_file(path)
    with database_errors(engine), engine.connect() as conn:
        state = _state_on(conn, url)
        conn.rollback()
    return state


def _migrate(engine: Engine, target: str, *, down: bool) -> tuple[str | None, str | None]:
    from sqlalchemy import text

    from calibctl.store.engine import WRITE_OPTION, database_errors, display_url, sqlite_path

    url = display_url(engine.url)
    _refuse_foreign_file(sqlite_path(engine.url))
    with database_errors(engine), engine.connect() as conn:
        conn.execution_options(**{WRITE_OPTION: True})
        with conn.begin():
            if conn.dialect.name == "postgresql":
                conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": _MIGRATION_LOCK_KEY})
            state = _state_on(conn, url)
            if state.status == "unknown":
                state.require_current()
            before = state.current
            from alembic import command

            cfg = alembic_config(conn)
            if down:
                command.downgrade(cfg, target)
            else:
                command.upgrade(cfg, target)
            after = _current_revision(conn)
    return before, after


def upgrade(engine: Engine, target: str = "head") -> tuple[str | None, str | None]:
    """Migrate to ``target`` keeping the data; returns (revision before, revision after)."""
    return _migrate(engine, target, down=False)


def downgrade(engine: Engine, target: str) -> tuple[str | None, str | None]:
    """Migrate down to ``target`` ("base" drops every calibctl table); returns (before, after)."""
    return _migrate(engine, target, down=True)


def state_of(url: str) -> SchemaState:
    """Where the database at ``url`` stands (does not create anything)."""
    from calibctl.store.engine import make_engine

    engine = make_engine(url)
    try:
        return read_state(engine)
    finally:
        engine.dispose()


def upgrade_url(url: str) -> tuple[str | None, str | None]:
    """Create or migrate the database at ``url`` to head, keeping its data; returns (before, after)."""
    from calibctl.store.engine import make_engine

    engine = make_engine(url)
    try:
        return upgrade(engine)
    finally:
        engine.dispose()
