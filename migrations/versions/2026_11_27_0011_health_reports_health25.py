"""health_reports: the health summaries robots send, append-only, not chained

Revision ID: 0011_health_reports_health25
Revises: 0010_fleet_diff25
Create Date: 2026-11-27

One row per report: the numbers as columns (``fleet trends`` reads them without decoding documents) and the
report's canonical JSON with its sha256. ``source_id`` is unique: a report sent twice is refused. Triggers
refuse
UPDATE and DELETE (and TRUNCATE on PostgreSQL, with 0001's calibctl_refuse_change()), as on every other table.
Not hash-chained: telemetry, at fleet volume (500 robots x 4 sensors x daily), see docs/fleet.md.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0011_health_reports_health25"
down_revision: str | Sequence[str] | None = "0010_fleet_diff25"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "health_reports"
MESSAGE = "health reports are append-only"


def upgrade() -> None:
    op.create_table(
        TABLE,
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("source_id", sa.String(128), nullable=False),
        sa.Column("serial", sa.String(128), nullable=False),
        sa.Column("robot", sa.String(128), nullable=False),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("rms_px", sa.Double(), nullable=True),
        sa.Column("verdict", sa.String(32), nullable=True),
        sa.Column("ratio", sa.Double(), nullable=True),
        sa.Column("sigma", sa.Double(), nullable=True),
        sa.Column("td_ms", sa.Double(), nullable=True),
        sa.Column("sigma_ms", sa.Double(), nullable=True),
        sa.Column("temperature_c", sa.Double(), nullable=True),
        sa.Column("ingested_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("payload_sha256", sa.String(64), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_health_reports"),
        sa.UniqueConstraint("source_id", name="uq_health_reports_source_id"),
    )
    op.create_index("ix_health_reports_serial_kind_at", TABLE, ["serial", "kind", "at"])
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
    op.drop_index("ix_health_reports_serial_kind_at", table_name=TABLE)
    op.drop_table(TABLE)
