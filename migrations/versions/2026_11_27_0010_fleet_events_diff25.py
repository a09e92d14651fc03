"""fleet_events: the fleet's log (robots, the versions they run, rollouts), chained and append-only

Revision ID: 0010_fleet_diff25
Revises: 0009_chain_sessions_reads26
Create Date: 2026-11-27

One table, one hash-chained stream for the store (``chain.STREAMS["fleet"]``, counter row ``version_counters``
scope ``chain``, key ``fleet``, written by the first event). Rows are never updated or deleted: triggers
refuse
UPDATE and DELETE (and TRUNCATE on PostgreSQL, with 0001's calibctl_refuse_change()), as on every other table.
``subject`` is the robot an event is about, or the rollout for the rollout kinds.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010_fleet_diff25"
down_revision: str | Sequence[str] | None = "0009_chain_sessions_reads26"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "fleet_events"
MESSAGE = "fleet events are append-only"


def upgrade() -> None:
    op.create_table(
        TABLE,
        sa.Column("id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("subject", sa.String(128), nullable=False),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("payload_sha256", sa.String(64), nullable=False),
        sa.Column("chain_seq", sa.Integer(), nullable=True),
        sa.Column("chain_prev", sa.String(64), nullable=True),
        sa.Column("chain_hash", sa.String(64), nullable=True),
        sa.Column("signature", sa.Text(), nullable=True),
        sa.Column("key_id", sa.String(64), nullable=True),
        sa.PrimaryKeyConstraint("id", name="pk_fleet_events"),
    )
    op.create_index("ix_fleet_events_subject_id", TABLE, ["subject", "id"])
    op.create_index("ix_fleet_events_chain_seq", TABLE, ["chain_seq"], unique=True)
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
    op.drop_index("ix_fleet_events_chain_seq", table_name=TABLE)
    op.drop_index("ix_fleet_events_subject_id", table_name=TABLE)
    op.drop_table(TABLE)
    op.execute("DELETE FROM version_counters WHERE scope = 'chain' AND key = 'fleet'")
