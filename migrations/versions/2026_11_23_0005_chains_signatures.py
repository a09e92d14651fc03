"""chains and signatures: a hash chain (and an optional Ed25519 signature) on every immutable record

Revision ID: 0005_chains_signatures
Revises: 0002_image_retention
Create Date: 2026-11-23

Board revisions, calibration artifacts and activation events get ``chain_seq``, ``chain_prev``,
``chain_hash``, ``signature`` and ``key_id`` (see calibctl/store/chain.py). Rows already stored are
chained here, in id order, unsigned (no key is at hand in a migration); the immutability triggers are
lifted for that one UPDATE and restored. Unique indexes on the chain positions make a forked chain
impossible even for two writers racing past calibctl's own lock.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

from calibctl.store import chain

revision: str = "0005_chains_signatures"
down_revision: str | Sequence[str] | None = "0003_rigs"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLES = ("board_revisions", "calibration_artifacts", "activation_events")
POSITIONS = {
    "board_revisions": ("ix_board_revisions_name_chain_seq", ["name", "chain_seq"]),
    "calibration_artifacts": ("ix_calibration_artifacts_serial_chain_seq", ["serial", "chain_seq"]),
    "activation_events": ("ix_activation_events_chain_seq", ["chain_seq"]),
}
COLUMNS = ("chain_seq", "chain_prev", "chain_hash", "signature", "key_id")


def upgrade() -> None:
    # Plain ADD COLUMN / CREATE INDEX: no batch copy of the tables, so their triggers stay in place.
    for table in TABLES:
        for column in chain.new_columns():
            op.add_column(table, column)
    chain.backfill_without_triggers(op.get_bind(), ("board", "artifact", "event"))
    for table, (name, columns) in POSITIONS.items():
        op.create_index(name, table, columns, unique=True)


def downgrade() -> None:
    conn = op.get_bind()
    for table, (name, _) in POSITIONS.items():
        op.drop_index(name, table_name=table)
    for table in TABLES:
        for column in COLUMNS:
            # SQLite >= 3.35 drops a column in place (a batch copy would lose the triggers).
            conn.execute(sa.text(f"ALTER TABLE {table} DROP COLUMN {column}"))
    conn.execute(sa.text("DELETE FROM version_counters WHERE scope = 'chain'"))
