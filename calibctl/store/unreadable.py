"""The error for a stored value that does not parse, shared by the ORM models, the codec and the plain
sqlite3 reads (kept apart so that none of them imports another for it)."""

from __future__ import annotations

from calibctl.errors import UnverifiedRecord


def unreadable_datetime(value: object) -> UnverifiedRecord:
    """A stored date and time that does not parse: someone edited the database outside calibctl."""
    return UnverifiedRecord(
        f"a stored date and time ({str(value)[:40]!r}) is unreadable: the database was edited "
        "outside calibctl",
        "restore the database from a backup or the records from exports",
    )
