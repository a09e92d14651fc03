"""``db verify``'s check that the database still refuses changes: every immutability trigger the migrations
created is there, on its table, raising, and (PostgreSQL) enabled.

The chains show a change after the fact; the triggers stop calibctl's own code paths and a careless
``UPDATE`` from making one. Someone with write access can drop them (SQLite: ``DROP TRIGGER``;
PostgreSQL: ``DROP TRIGGER`` or ``ALTER TABLE ... DISABLE TRIGGER``) and leave them dropped, so that
any later session changes rows unrefused: that is a finding in itself, whatever the rows say.
"""

from __future__ import annotations

from sqlalchemy import text
from sqlalchemy.orm import Session

from calibctl.store.models import IMMUTABLE_TABLES

ACCEPTED_ONLY = {
    "activation_events": "trg_activation_events_accepted_only",
    "rig_activation_events": "trg_rig_activation_events_accepted_only",
}
"""The INSERT triggers that refuse to activate a version that is not accepted."""


def expected(dialect: str) -> dict[str, str]:
    """Trigger name -> its table, as the migrations create them on ``dialect``."""
    actions = ("no_update", "no_delete") if dialect == "sqlite" else ("immutable", "no_truncate")
    names = {f"trg_{table}_{action}": table for table in IMMUTABLE_TABLES for action in actions}
    return names | {name: table for table, name in ACCEPTED_ONLY.items()}


def _sqlite_intact(name: str, table: str, sql: str) -> bool:
    """The trigger's text is what the migration wrote (an immutability trigger: exactly; an accepted-only
    one: it still raises on a status other than accepted): a same-named ``WHEN 0`` trigger refuses nothing."""
    if name in ACCEPTED_ONLY.values():
        return "RAISE(ABORT" in sql and "IS NOT 'accepted'" in sql
    action = "UPDATE" if name.endswith("_no_update") else "DELETE"
    return " ".join(sql.split()) == (
        f"CREATE TRIGGER {name} BEFORE {action} ON {table} "
        f"BEGIN SELECT RAISE(ABORT, '{IMMUTABLE_TABLES.get(table, '')}'); END"
    )


def _sqlite(s: Session) -> dict[str, tuple[str, str | None]]:
    rows = s.execute(text("SELECT name, tbl_name, sql FROM sqlite_master WHERE type = 'trigger'")).all()
    return {
        str(name): (str(table), None if _sqlite_intact(str(name), str(table), str(sql)) else "changed")
        for name, table, sql in rows
    }


_PG_FUNCTIONS = {
    "trg_activation_events_accepted_only": "calibctl_accepted_only",
    "trg_rig_activation_events_accepted_only": "calibctl_rig_accepted_only",
}
"""The function each PostgreSQL trigger calls (the immutability ones: ``calibctl_refuse_change``)."""


def _postgresql(s: Session) -> dict[str, tuple[str, str | None]]:
    rows = s.execute(
        text(
            "SELECT t.tgname, c.relname, t.tgenabled <> 'D', p.proname, p.prosrc FROM pg_trigger t "
            "JOIN pg_class c ON c.oid = t.tgrelid JOIN pg_namespace n ON n.oid = c.relnamespace "
            "JOIN pg_proc p ON p.oid = t.tgfoid WHERE NOT t.tgisinternal AND n.nspname = current_schema()"
        )
    ).all()
    found: dict[str, tuple[str, str | None]] = {}
    for name, table, enabled, func, src in rows:
        intact = str(func) == _PG_FUNCTIONS.get(
            str(name), "calibctl_refuse_change"
        ) and "RAISE EXCEPTION" in str(src)
        found[str(name)] = (str(table), None if intact and enabled else "disabled" if intact else "changed")
    return found


def problems(s: Session) -> list[str]:
    """One line per missing, moved, disabled or defanged trigger (empty when all are in place)."""
    dialect = s.get_bind().dialect.name
    found = _sqlite(s) if dialect == "sqlite" else _postgresql(s)
    out = []
    for name, table in sorted(expected(dialect).items()):
        if name not in found or found[name][0] != table:
            out.append(
                f"the immutability trigger {name} on {table} is missing: the database no longer refuses "
                "changes to that table"
            )
        elif found[name][1] is not None:
            out.append(
                f"the immutability trigger {name} on {table} was {found[name][1]}: the database no longer "
                "refuses changes to that table"
            )
    return out
