"""chain rigs and checks: rig versions, rig activation events and check events join the hash chains

Revision ID: 0007_chain_rigs_checks
Revises: 0006_check_events
Create Date: 2026-11-23

Like 0005 for the camera tables: ``rig_calibrations`` (one chain per rig), ``rig_activation_events``
(one chain for the store) and ``check_events`` (one chain per serial) get ``chain_seq``,
``chain_prev``, ``chain_hash``, ``signature`` and ``key_id`` (see calibctl/store/chain.py). Rows
already stored are chained here, in id order, unsigned; the immutability triggers are lifted for
that one UPDATE and restored. Unique indexes on the chain positions make a forked chain impossible.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

from calibctl.store import chain

revision: str = "0007_chain_rigs_checks"
down_revision: str | Sequence[str] | None = "0006_check_events"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

STREAMS = ("rig", "rig_event", "check")
TABLES = ("rig_calibrations", "rig_activation_events", "check_events")
POSITIONS = {
    "rig_calibrations": ("ix_rig_calibrations_rig_chain_seq", ["rig", "chain_seq"]),
    "rig_activation_events": ("ix_rig_activation_events_chain_seq", ["chain_seq"]),
    "check_events": ("ix_check_events_serial_chain_seq", ["serial", "chain_seq"]),
}
COLUMNS = ("chain_seq", "chain_prev", "chain_hash", "signature", "key_id")


def upgrade() -> None:
    # Plain ADD COLUMN / CREATE INDEX: no batch copy of the tables, so their triggers stay in place.
    for table in TABLES:
        for column in chain.new_columns():
            op.add_column(table, column)
    chain.backfill_without_triggers(op.get_bind(), STREAMS)
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
    conn.execute(
        sa.text(
            "DELETE FROM version_counters WHERE scope = 'check' OR (scope = 'chain' AND key = 'rig_event')"
        )
    )
