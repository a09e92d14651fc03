"""check_events: re-tests of a calibration on fresh views (calibctl check), immutable

Revision ID: 0006_check_events
Revises: 0003_rigs
Create Date: 2026-11-23

Like the other tables: rows are never updated or deleted (triggers refuse UPDATE and DELETE, and
TRUNCATE on PostgreSQL, with 0001's calibctl_refuse_change()). A check names an existing version.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006_check_events"
down_revision: str | Sequence[str] | None = "0005_chains_signatures"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "check_events"
MESSAGE = "check events are append-only"


def upgrade() -> None:
    op.create_table(
        TABLE,
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("check_id", sa.String(12), nullable=False),
        sa.Column("serial", sa.String(128), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("passed", sa.Boolean(), nullable=False),
        sa.Column("at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("payload_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_check_events"),
        sa.UniqueConstraint("check_id", name="uq_check_events_check_id"),
        sa.ForeignKeyConstraint(
            ["serial", "version"],
            ["calibration_artifacts.serial", "calibration_artifacts.version"],
            name="fk_check_events_serial_version_calibration_artifacts",
        ),
    )
    op.create_index("ix_check_events_serial_id", TABLE, ["serial", "id"])
    dialect = op.get_context().dialect.name
    if dialect == "sqlite":
        for action in ("UPDATE", "DELETE"):
            op.execute(
                f"CREATE TRIGGER trg_{TABLE}_no_{action.lower()} BEFORE {action} ON {TABLE} "
                f"BEGIN SELECT RAISE(ABORT, '{MESSAGE}'); END"
            )
    elif dialect == "postgresql":
        op.execute(
            f"CREATE TRIGGER trg_{TABLE}_immutable BEFORE UPDATE OR DELETE ON {TABLE} "
            f"FOR EACH ROW EXECUTE FUNCTION calibctl_refuse_change('{MESSAGE}')"
        )
        op.execute(
            f"CREATE TRIGGER trg_{TABLE}_no_truncate BEFORE TRUNCATE ON {TABLE} "
            f"FOR EACH STATEMENT EXECUTE FUNCTION calibctl_refuse_change('{MESSAGE}')"
        )
    else:  # pragma: no cover - calibctl refuses other URLs before it gets here
        raise RuntimeError(f"calibctl migrations support sqlite and postgresql, not {dialect}")


def downgrade() -> None:
    # Dropping a table drops its triggers; DROP does not fire row triggers on either backend.
    op.drop_index("ix_check_events_serial_id", table_name=TABLE)
    op.drop_table(TABLE)
