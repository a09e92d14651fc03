"""rigs: rig definitions, rig sessions, rig calibrations and their activation events, immutable

Revision ID: 0003_rigs
Revises: 0002_image_retention
Create Date: 2026-11-23

Like the camera tables of 0001: rows are never updated or deleted (triggers refuse UPDATE and DELETE,
and TRUNCATE on PostgreSQL), and an activation event may only name an accepted rig calibration.
The trigger function calibctl_refuse_change() of 0001 is reused on PostgreSQL.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003_rigs"
down_revision: str | Sequence[str] | None = "0002_image_retention"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

IMMUTABLE = {
    "rig_definitions": "rig definitions are immutable",
    "rig_sessions": "rig sessions are immutable",
    "rig_calibrations": "rig calibrations are immutable",
    "rig_activation_events": "rig activation events are append-only",
}
ACCEPTED_ONLY = "only an accepted rig calibration can become active"


def _create_tables() -> None:
    op.create_table(
        "rig_definitions",
        sa.Column("name", sa.String(128), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("payload_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("name", name="pk_rig_definitions"),
    )
    op.create_table(
        "rig_sessions",
        sa.Column("rig_session_id", sa.String(12), nullable=False),
        sa.Column("rig", sa.String(128), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("payload_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("rig_session_id", name="pk_rig_sessions"),
    )
    op.create_index("ix_rig_sessions_rig_created_at", "rig_sessions", ["rig", "created_at"])
    op.create_table(
        "rig_calibrations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("rig", sa.String(128), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("content_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_rig_calibrations"),
        sa.UniqueConstraint("rig", "version", name="uq_rig_calibrations_rig_version"),
        sa.CheckConstraint("version >= 1", name="ck_rig_calibrations_version_positive"),
        sa.CheckConstraint("status IN ('accepted', 'rejected')", name="ck_rig_calibrations_status_known"),
    )
    op.create_table(
        "rig_activation_events",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("rig", sa.String(128), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("previous_version", sa.Integer(), nullable=True),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("actor", sa.Text(), nullable=False),
        sa.Column("station", sa.Text(), nullable=False),
        sa.Column("at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_rig_activation_events"),
        sa.ForeignKeyConstraint(
            ["rig", "version"],
            ["rig_calibrations.rig", "rig_calibrations.version"],
            name="fk_rig_activation_events_rig_version_rig_calibrations",
        ),
        sa.CheckConstraint("kind IN ('activate', 'rollback')", name="ck_rig_activation_events_kind_known"),
    )
    op.create_index("ix_rig_activation_events_rig_id", "rig_activation_events", ["rig", "id"])


def _create_triggers_sqlite() -> None:
    for table, message in IMMUTABLE.items():
        for action in ("UPDATE", "DELETE"):
            op.execute(
                f"CREATE TRIGGER trg_{table}_no_{action.lower()} BEFORE {action} ON {table} "
                f"BEGIN SELECT RAISE(ABORT, '{message}'); END"
            )
    op.execute(
        "CREATE TRIGGER trg_rig_activation_events_accepted_only BEFORE INSERT ON rig_activation_events "
        "WHEN (SELECT status FROM rig_calibrations "
        "      WHERE rig = NEW.rig AND version = NEW.version) IS NOT 'accepted' "
        f"BEGIN SELECT RAISE(ABORT, '{ACCEPTED_ONLY}'); END"
    )


def _create_triggers_postgresql() -> None:
    op.execute(
        "CREATE FUNCTION calibctl_rig_accepted_only() RETURNS trigger LANGUAGE plpgsql AS $$ "
        "BEGIN "
        "  IF NOT EXISTS (SELECT 1 FROM rig_calibrations "
        "                 WHERE rig = NEW.rig AND version = NEW.version AND status = 'accepted') THEN "
        f"    RAISE EXCEPTION USING MESSAGE = '{ACCEPTED_ONLY}: ' || NEW.rig || '@' || NEW.version, "
        "                          ERRCODE = 'restrict_violation'; "
        "  END IF; "
        "  RETURN NEW; "
        "END $$"
    )
    for table, message in IMMUTABLE.items():
        op.execute(
            f"CREATE TRIGGER trg_{table}_immutable BEFORE UPDATE OR DELETE ON {table} "
            f"FOR EACH ROW EXECUTE FUNCTION calibctl_refuse_change('{message}')"
        )
        op.execute(
            f"CREATE TRIGGER trg_{table}_no_truncate BEFORE TRUNCATE ON {table} "
            f"FOR EACH STATEMENT EXECUTE FUNCTION calibctl_refuse_change('{message}')"
        )
    op.execute(
        "CREATE TRIGGER trg_rig_activation_events_accepted_only BEFORE INSERT ON rig_activation_events "
        "FOR EACH ROW EXECUTE FUNCTION calibctl_rig_accepted_only()"
    )


def upgrade() -> None:
    _create_tables()
    dialect = op.get_context().dialect.name
    if dialect == "sqlite":
        _create_triggers_sqlite()
    elif dialect == "postgresql":
        _create_triggers_postgresql()
    else:  # pragma: no cover - calibctl refuses other URLs before it gets here
        raise RuntimeError(f"calibctl migrations support sqlite and postgresql, not {dialect}")


def downgrade() -> None:
    # Dropping a table drops its triggers; DROP does not fire row triggers on either backend.
    op.drop_index("ix_rig_activation_events_rig_id", table_name="rig_activation_events")
    op.drop_table("rig_activation_events")
    op.drop_table("rig_calibrations")
    op.drop_index("ix_rig_sessions_rig_created_at", table_name="rig_sessions")
    op.drop_table("rig_sessions")
    op.drop_table("rig_definitions")
    if op.get_context().dialect.name == "postgresql":
        op.execute("DROP FUNCTION calibctl_rig_accepted_only()")
