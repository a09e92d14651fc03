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


def _columns() -> list[sa.Column]:
    return [
        sa.Column("chain_seq", sa.Integer(), nullable=True),
        sa.Column("chain_prev", sa.String(64), nullable=True),
        sa.Column("chain_hash", sa.String(64), nullable=True),
        sa.Column("signature", sa.Text(), nullable=True),
        sa.Column("key_id", sa.String(64), nullable=True),
    ]


def _backfill_without_triggers() -> None:
    conn = op.get_bind()
    if conn.dialect.name == "sqlite":
        names = ", ".join(f"'trg_{t}_no_update'" for t in TABLES)
        saved = conn.execute(sa.text(f"SELECT name, sql FROM sqlite_master WHERE type = 'trigger' AND name IN ({names})")).all()
        for name, _ in saved:
            conn.execute(sa.text(f"DROP TRIGGER {name}"))
        chain.backfill(conn)
        for _, sql in saved:
            conn.execute(sa.text(sql))
        return
    for table in TABLES:
        conn.execute(sa.text(f"ALTER TABLE {table} DISABLE TRIGGER trg_{table}_immutable"))
    chain.backfill(conn)
    for table in TABLES:
        conn.execute(sa.text(f"ALTER TABLE {table} ENABLE TRIGGER trg_{table}_immutable"))


def upgrade() -> None:
    # Plain ADD COLUMN / CREATE INDEX: no batch copy of the tables, so their triggers stay in place.
    for table in TABLES:
        for column in _columns():
            op.add_column(table, column)
    _backfill_without_triggers()
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
