"""What an attacker with access to the database files or a superuser login can do (for tamper tests)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import psycopg
from sqlalchemy.engine import make_url


def _sqlite_file(url: str) -> Path | None:
    parsed = make_url(url)
    return Path(parsed.database) if parsed.get_backend_name() == "sqlite" and parsed.database else None


def _libpq(url: str) -> str:
    return url.replace("postgresql+psycopg://", "postgresql://", 1)


def patch_stored_bytes(url: str, table: str, old: str, new: str) -> None:
    """Replace ``old`` by ``new`` (same length) in the stored payload of ``table``, underneath calibctl.

    SQLite: edit the database file's bytes directly (the store must be closed, so the WAL has been
    checkpointed into the file). PostgreSQL: as a superuser, disable the immutability trigger,
    UPDATE the payload, enable the trigger again.
    """
    assert len(old) == len(new) and old != new
    path = _sqlite_file(url)
    if path is not None:
        wal = path.with_name(path.name + "-wal")
        assert not wal.exists() or wal.stat().st_size == 0, (
            "close the store first (its WAL is not checkpointed)"
        )
        data = path.read_bytes()
        assert data.count(old.encode()) == 1, f"{old!r} occurs {data.count(old.encode())} times in {path}"
        path.write_bytes(data.replace(old.encode(), new.encode()))
        return
    with psycopg.connect(_libpq(url), autocommit=True) as conn:
        conn.execute(f"ALTER TABLE {table} DISABLE TRIGGER trg_{table}_immutable")
        changed = conn.execute(
            f"UPDATE {table} SET payload = replace(payload, %s, %s) WHERE strpos(payload, %s) > 0",
            (old, new, old),
        ).rowcount
        conn.execute(f"ALTER TABLE {table} ENABLE TRIGGER trg_{table}_immutable")
    assert changed == 1, f"{old!r} found in {changed} rows of {table}"


def forge_activation(url: str, serial: str, version: int) -> None:
    """Insert an activation event the accepted-only trigger would refuse (by removing the trigger first)."""
    insert = (
        "INSERT INTO activation_events (serial, version, previous_version, kind, actor, station, at, reason) "
        f"VALUES ('{serial}', {version}, NULL, 'rollback', 'mallory', 'nowhere', '2026-01-01 00:00:00', "
        "'forged')"
    )
    path = _sqlite_file(url)
    if path is not None:
        conn = sqlite3.connect(path, isolation_level=None)
        try:
            (sql,) = conn.execute(
                "SELECT sql FROM sqlite_master WHERE name = 'trg_activation_events_accepted_only'"
            ).fetchone()
            conn.execute("DROP TRIGGER trg_activation_events_accepted_only")
            conn.execute(insert)
            conn.execute(sql)  # put back, as the PostgreSQL branch re-enables it
        finally:
            conn.close()
        return
    with psycopg.connect(_libpq(url), autocommit=True) as pg:
        pg.execute("ALTER TABLE activation_events DISABLE TRIGGER trg_activation_events_accepted_only")
        pg.execute(insert)
        pg.execute("ALTER TABLE activation_events ENABLE TRIGGER trg_activation_events_accepted_only")


def run_underneath(
    url: str, *statements: str, params: tuple[object, ...] = (), keep_triggers_dropped: bool = False
) -> None:
    """Run SQL the way someone with write access to the database would: SQLite with every calibctl
    trigger dropped (and, as a careful forger does, re-created afterwards unless ``keep_triggers_dropped``),
    PostgreSQL as a superuser with triggers (and foreign keys) switched off for the session."""
    path = _sqlite_file(url)
    if path is not None:
        conn = sqlite3.connect(path, isolation_level=None)
        try:
            saved = conn.execute("SELECT name, sql FROM sqlite_master WHERE type = 'trigger'").fetchall()
            for name, _ in saved:
                conn.execute(f"DROP TRIGGER {name}")
            for statement in statements:
                conn.execute(statement.replace("%s", "?"), params if "%s" in statement else ())
            if not keep_triggers_dropped:
                for _, sql in saved:
                    conn.execute(sql)
        finally:
            conn.close()
        return
    with psycopg.connect(_libpq(url), autocommit=True) as pg:
        pg.execute("SET session_replication_role = replica")
        for statement in statements:
            pg.execute(statement, params if "%s" in statement else ())  # type: ignore[arg-type]
        if keep_triggers_dropped:
            for table, name in _pg_triggers(pg):
                pg.execute(f"DROP TRIGGER {name} ON {table}")


def _pg_triggers(pg: psycopg.Connection) -> list[tuple[str, str]]:
    rows = pg.execute(
        "SELECT c.relname, t.tgname FROM pg_trigger t JOIN pg_class c ON c.oid = t.tgrelid "
        "WHERE NOT t.tgisinternal AND t.tgname LIKE 'trg_%%'"
    ).fetchall()
    return [(str(table), str(name)) for table, name in rows]


def rechain(url: str) -> None:
    """What a careful forger does after an edit: recompute every chain hash (keeping positions and the
    signature columns, since without the key no new signature can be made)."""
    from sqlalchemy import select

    from calibctl.store import chain
    from calibctl.store.engine import make_engine

    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            updates = []
            for stream in chain.STREAMS.values():
                t = stream.table
                prev, key = None, None
                rows = (
                    conn.execute(select(t).order_by(*[t.c[k] for k in stream.key], t.c.chain_seq))
                    .mappings()
                    .all()
                )
                for row in rows:
                    if stream.key_of(row) != key:
                        key, prev = stream.key_of(row), None
                    digest = chain.record_hash(stream, key, row["chain_seq"], prev, chain.body(row))
                    updates.append((t.name, prev, digest, row["id"]))
                    prev = digest
    finally:
        engine.dispose()
    for table, prev, digest, row_id in updates:
        run_underneath(
            url,
            f"UPDATE {table} SET chain_prev = %s, chain_hash = %s WHERE id = %s",
            params=(prev, digest, row_id),
        )
