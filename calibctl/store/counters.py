"""Version allocation that stays correct when several stations write at once.

Each (scope, key) -- ('artifact', serial) or ('board', name) -- has one row in ``version_counters``.
Allocating the next version is a single upsert that bumps the row and returns the new value inside
the caller's transaction:

* PostgreSQL: the upsert takes the row lock, so a second writer for the same serial waits (bounded
  by ``lock_timeout``) until the first commits or rolls back, then sees its value. Different serials
  never wait for each other.
* SQLite: write transactions start with ``BEGIN IMMEDIATE``, so writers are serialised anyway.

A rolled-back or crashed transaction rolls its bump back with it: no version is lost or half-made.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import Table, case, select
from sqlalchemy.orm import Session

from calibctl.artifacts.common import MAX_VERSION
from calibctl.errors import UsageError
from calibctl.store.models import CounterRow

_counters: Table = CounterRow.__table__  # type: ignore[assignment]


def _insert(session: Session) -> Any:
    # The dialect modules are imported here: sqlalchemy.dialects.postgresql alone costs ~0.1 s of
    # start-up for commands that never write.
    if session.get_bind().dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert as pg_insert

        return pg_insert(_counters)
    from sqlalchemy.dialects.sqlite import insert as sqlite_insert

    return sqlite_insert(_counters)


def peek(session: Session, scope: str, key: str) -> int | None:
    """The last value handed out for (scope, key); None when none was."""
    stmt = select(_counters.c.last_value).where(_counters.c.scope == scope, _counters.c.key == key)
    return session.execute(stmt).scalar_one_or_none()


def next_value(session: Session, scope: str, key: str) -> int:
    """Bump and return the counter of (scope, key); the first value is 1. At ``MAX_VERSION`` (the
    largest value a version column holds on both backends) it refuses instead of overflowing."""
    # One round trip: the bump itself refuses a counter at the limit (no row comes back), so the row is
    # read first only on that failure path, to name its value.
    stmt = _insert(session).values(scope=scope, key=key, last_value=1)
    stmt = stmt.on_conflict_do_update(
        index_elements=[_counters.c.scope, _counters.c.key],
        set_={"last_value": _counters.c.last_value + 1},
        where=_counters.c.last_value < MAX_VERSION,
    ).returning(_counters.c.last_value)
    value = session.execute(stmt).scalar_one_or_none()
    if value is None:
        raise UsageError(
            f"{scope} {key} has reached version {peek(session, scope, key)}, the largest a store holds "
            f"({MAX_VERSION})",
            "use a new serial/name; versions are never reused",
        )
    return int(value)


def raise_to(session: Session, scope: str, key: str, value: int) -> int:
    """Make sure the counter of (scope, key) is at least ``value`` (an imported version); returns it."""
    stmt = _insert(session).values(scope=scope, key=key, last_value=value)
    stmt = stmt.on_conflict_do_update(
        index_elements=[_counters.c.scope, _counters.c.key],
        set_={
            "last_value": case(
                (_counters.c.last_value < stmt.excluded.last_value, stmt.excluded.last_value),
                else_=_counters.c.last_value,
            )
        },
    ).returning(_counters.c.last_value)
    return int(session.execute(stmt).scalar_one())


def lock(session: Session, scope: str, key: str) -> int | None:
    """Hold the counter row of (scope, key) until the transaction ends (PostgreSQL ``FOR UPDATE``;
    SQLite's write transactions hold the database lock already). Returns the counter, None if absent."""
    stmt = select(_counters.c.last_value).where(_counters.c.scope == scope, _counters.c.key == key)
    return session.execute(stmt.with_for_update()).scalar_one_or_none()
