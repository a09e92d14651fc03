"""chain health reports: the robots' health reports join the hash chains (one stream for the store)

Revision ID: 0016_chain_health_reports
Revises: 0015_checkpoints_fleet_ckpt
Create Date: 2026-12-07

A rollout's promote decides on the canary robots' health reports. Kept with only their payload sha256, a
failing report edited to pass (the hash recomputed) or deleted before the promote went unseen. So, like 0009,
``health_reports`` gets ``chain_seq``, ``chain_prev``, ``chain_hash``, ``signature`` and ``key_id``: one
stream for the store, counted in ``version_counters`` scope ``chain``, key ``health`` (the row ``fleet
ingest`` locks). Rows already stored are chained in id order, unsigned, with the immutability triggers lifted
for that one UPDATE and restored; a unique index on the position refuses a fork.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

from calibctl.store import chain

revision: str = "0016_chain_health_reports"
down_revision: str | Sequence[str] | None = "0015_checkpoints_fleet_ckpt"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "health_reports"
INDEX = "ix_health_reports_chain_seq"
COLUMNS = ("chain_seq", "chain_prev", "chain_hash", "signature", "key_id")


def upgrade() -> None:
    # Plain ADD COLUMN / CREATE INDEX: no batch copy of the table, so its triggers stay in place.
    for column in chain.new_columns():
        op.add_column(TABLE, column)
    chain.backfill_without_triggers(op.get_bind(), ("health",))
    op.create_index(INDEX, TABLE, ["chain_seq"], unique=True)


def downgrade() -> None:
    conn = op.get_bind()
    op.drop_index(INDEX, table_name=TABLE)
    for column in COLUMNS:
        # SQLite >= 3.35 drops a column in place (a batch copy would lose the triggers).
        conn.execute(sa.text(f"ALTER TABLE {TABLE} DROP COLUMN {column}"))
    conn.execute(sa.text("DELETE FROM version_counters WHERE scope = 'chain' AND key = 'health'"))
