"""chain rig definitions: the registered rigs join the hash chains (one stream for the store)

Revision ID: 0008_chain_rig_definitions
Revises: 0007_chain_rigs_checks
Create Date: 2026-11-23

A rig definition names the members, the root and the design baselines with their tolerances: rig lint
compares every stored version with them and every later rig solve starts from them, so widening a
tolerance (its payload_sha256 recomputed) would pass a bent rig without any record changing. Like 0007:
``rig_definitions`` gets ``chain_seq``, ``chain_prev``, ``chain_hash``, ``signature``, ``key_id``, and
an ``id`` (its position in the one store-wide stream; the name stays the primary key the other rig
tables use). Rows already stored are numbered in (created_at, name) order and chained, unsigned, with
the immutability triggers lifted for that one UPDATE and restored; the stream's counter row
(``version_counters`` scope ``chain``, key ``rig_definition``) is written. Unique indexes on ``id`` and
the position refuse a fork.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

from calibctl.store import chain

revision: str = "0008_chain_rig_definitions"
down_revision: str | Sequence[str] | None = "0007_chain_rigs_checks"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "rig_definitions"
INDEXES = {"ix_rig_definitions_id": ["id"], "ix_rig_definitions_chain_seq": ["chain_seq"]}
COLUMNS = ("id", "chain_seq", "chain_prev", "chain_hash", "signature", "key_id")


def _number(conn: sa.Connection) -> None:
    names = conn.execute(sa.text(f"SELECT name FROM {TABLE} ORDER BY created_at, name")).scalars().all()
    for position, name in enumerate(names, start=1):
        conn.execute(
            sa.text(f"UPDATE {TABLE} SET id = :id WHERE name = :name"), {"id": position, "name": name}
        )


def upgrade() -> None:
    # Plain ADD COLUMN / CREATE INDEX: no batch copy of the table, so its triggers stay in place.
    op.add_column(TABLE, sa.Column("id", sa.Integer(), nullable=True))
    for column in chain.new_columns():
        op.add_column(TABLE, column)
    chain.backfill_without_triggers(op.get_bind(), ("rig_definition",), prepare=_number)
    for name, columns in INDEXES.items():
        op.create_index(name, TABLE, columns, unique=True)


def downgrade() -> None:
    conn = op.get_bind()
    for name in INDEXES:
        op.drop_index(name, table_name=TABLE)
    for column in COLUMNS:
        # SQLite >= 3.35 drops a column in place (a batch copy would lose the triggers).
        conn.execute(sa.text(f"ALTER TABLE {TABLE} DROP COLUMN {column}"))
    conn.execute(sa.text("DELETE FROM version_counters WHERE scope = 'chain' AND key = 'rig_definition'"))
