"""initial schema: boards, capture sessions, calibration artifacts, activation events, immutability triggers

Revision ID: 0001_initial
Revises:
Create Date: 2026-11-22

Board revisions, capture sessions, calibration artifacts and activation events are immutable in
the database itself: triggers refuse UPDATE and DELETE on their rows (and TRUNCATE on PostgreSQL),
whoever connects, and refuse an activation event whose artifact is not accepted.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0001_initial"
down_revision: str | Sequence[str] | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

IMMUTABLE = {
    "board_revisions": "board revisions are immutable",
    "capture_sessions": "capture sessions are immutable",
    "calibration_artifacts": "calibration artifacts are immutable",
    "activation_events": "activation events are append-only",
}
ACCEPTED_ONLY = "only an accepted calibration can become active"


def _create_tables() -> None:
    op.create_table(
        "board_revisions",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(64), nullable=False),
        sa.Column("revision", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("measurement_status", sa.String(16), nullable=False),
        sa.Column("square_size_m", sa.Double(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("payload_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_board_revisions"),
        sa.UniqueConstraint("name", "revision", name="uq_board_revisions_name_revision"),
        sa.CheckConstraint("revision >= 1", name="ck_board_revisions_revision_positive"),
    )
    op.create_table(
        "capture_sessions",
        sa.Column("session_id", sa.String(12), nullable=False),
        sa.Column("serial", sa.String(128), nullable=False),
        sa.Column("board_ref", sa.String(80), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("station", sa.Text(), nullable=False),
        sa.Column("operator", sa.Text(), nullable=False),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("finished_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("payload_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("session_id", name="pk_capture_sessions"),
    )
    op.create_index("ix_capture_sessions_serial_started_at", "capture_sessions", ["serial", "started_at"])
    op.create_table(
        "calibration_artifacts",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("serial", sa.String(128), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("rms_px", sa.Double(), nullable=False),
        sa.Column("sigma_fx_px", sa.Double(), nullable=True),
        sa.Column("station", sa.Text(), nullable=False),
        sa.Column("operator", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("board_ref", sa.String(80), nullable=False),
        sa.Column("session_id", sa.String(12), nullable=True),
        sa.Column("stored_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("content_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_calibration_artifacts"),
        sa.UniqueConstraint("serial", "version", name="uq_calibration_artifacts_serial_version"),
        sa.CheckConstraint("version >= 1", name="ck_calibration_artifacts_version_positive"),
        sa.CheckConstraint(
            "status IN ('accepted', 'rejected')", name="ck_calibration_artifacts_status_known"
        ),
    )
    op.create_index("ix_calibration_artifacts_status", "calibration_artifacts", ["status"])
    op.create_table(
        "activation_events",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("serial", sa.String(128), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("previous_version", sa.Integer(), nullable=True),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("actor", sa.Text(), nullable=False),
        sa.Column("station", sa.Text(), nullable=False),
        sa.Column("at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_activation_events"),
        sa.ForeignKeyConstraint(
            ["serial", "version"],
            ["calibration_artifacts.serial", "calibration_artifacts.version"],
            name="fk_activation_events_serial_version_calibration_artifacts",
        ),
        sa.CheckConstraint("kind IN ('activate', 'rollback')", name="ck_activation_events_kind_known"),
    )
    op.create_index("ix_activation_events_serial_id", "activation_events", ["serial", "id"])
    op.create_table(
        "version_counters",
        sa.Column("scope", sa.String(16), nullable=False),
        sa.Column("key", sa.String(128), nullable=False),
        sa.Column("last_value", sa.Integer(), nullable=False),
        sa.PrimaryKeyConstraint("scope", "key", name="pk_version_counters"),
    )


def _create_triggers_sqlite() -> None:
    for table, message in IMMUTABLE.items():
        for action in ("UPDATE", "DELETE"):
            op.execute(
                f"CREATE TRIGGER trg_{table}_no_{action.lower()} BEFORE {action} ON {table} "
                f"BEGIN SELECT RAISE(ABORT, '{message}'); END"
            )
    op.execute(
        "CREATE TRIGGER trg_activation_events_accepted_only BEFORE INSERT ON activation_events "
        "WHEN (SELECT status FROM calibration_artifacts "
        "      WHERE serial = NEW.serial AND version = NEW.version) IS NOT 'accepted' "
        f"BEGIN SELECT RAISE(ABORT, '{ACCEPTED_ONLY}'); END"
    )


def _create_triggers_postgresql() -> None:
    op.execute(
        "CREATE FUNCTION calibctl_refuse_change() RETURNS trigger LANGUAGE plpgsql AS $$ "
        "BEGIN RAISE EXCEPTION USING MESSAGE = TG_ARGV[0], ERRCODE = 'restrict_violation'; END $$"
    )
    op.execute(
        "CREATE FUNCTION calibctl_accepted_only() RETURNS trigger LANGUAGE plpgsql AS $$ "
        "BEGIN "
        "  IF NOT EXISTS (SELECT 1 FROM calibration_artifacts "
        "                 WHERE serial = NEW.serial AND version = NEW.version AND status = 'accepted') THEN "
        f"    RAISE EXCEPTION USING MESSAGE = '{ACCEPTED_ONLY}: ' || NEW.serial || '@' || NEW.version, "
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
        "CREATE TRIGGER trg_activation_events_accepted_only BEFORE INSERT ON activation_events "
        "FOR EACH ROW EXECUTE FUNCTION calibctl_accepted_only()"
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
    op.drop_table("version_counters")
    op.drop_index("ix_activation_events_serial_id", table_name="activation_events")
    op.drop_table("activation_events")
    op.drop_index("ix_calibration_artifacts_status", table_name="calibration_artifacts")
    op.drop_table("calibration_artifacts")
    op.drop_index("ix_capture_sessions_serial_started_at", table_name="capture_sessions")
    op.drop_table("capture_sessions")
    op.drop_table("board_revisions")
    if op.get_context().dialect.name == "postgresql":
        op.execute("DROP FUNCTION calibctl_accepted_only()")
        op.execute("DROP FUNCTION calibctl_refuse_change()")
