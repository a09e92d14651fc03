"""chain capture sessions: the cameras' capture sessions join the hash chains (one stream per serial)

Revision ID: 0009_chain_sessions_reads26
Revises: 0008_chain_rig_definitions
Create Date: 2026-11-27

A capture session holds the corners every later solve, check and report of its camera reads. Its
payload_sha256 alone could be recomputed after an edit (edited corners went unseen by every `db verify` mode),
so like 0008: ``capture_sessions`` gets ``chain_seq``, ``chain_prev``, ``chain_hash``, ``signature``,
``key_id`` and an ``id`` (the session id stays the primary key the artifacts and rig sessions name). One
stream per serial, counted in ``version_counters`` scope ``session``, key = serial (that row is the lock
``Store.add_session`` takes, so stations capturing different cameras never wait on each other for long; the
ids come from the store-wide counter scope ``id``, key ``capture_sessions``, which catches up with the ids
given here on its first use).
Rows already stored are numbered in (started_at, session_id) order and chained, unsigned, with the
immutability triggers lifted for that one UPDATE and restored, so an old store keeps verifying. Unique
indexes on ``id`` and on (serial, position) refuse a fork.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

from calibctl.store import chain

revision: str = "0009_chain_sessions_reads26"
down_revision: str | Sequence[str] | None = "0008_chain_rig_definitions"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "capture_sessions"
INDEXES = {"ix_capture_sessions_id": ["id"], "ix_capture_sessions_serial_chain_seq": ["serial", "chain_seq"]}
COLUMNS = ("id", "chain_seq", "chain_prev", "chain_hash", "signature", "key_id")


def _number(conn: sa.Connection) -> None:
    ids = (
        conn.execute(sa.text(f"SELECT session_id FROM {TABLE} ORDER BY started_at, session_id"))
        .scalars()
        .all()
    )
    for position, session_id in enumerate(ids, start=1):
        conn.execute(
            sa.text(f"UPDATE {TABLE} SET id = :id WHERE session_id = :sid"),
            {"id": position, "sid": session_id},
        )


def upgrade() -> None:
    # Plain ADD COLUMN / CREATE INDEX: no batch copy of the table, so its triggers stay in place.
    op.add_column(TABLE, sa.Column("id", sa.Integer(), nullable=True))
    for column in chain.new_columns():
        op.add_column(TABLE, column)
    chain.backfill_without_triggers(op.get_bind(), ("session",), prepare=_number)
    for name, columns in INDEXES.items():
        op.create_index(name, TABLE, columns, unique=True)


def downgrade() -> None:
    conn = op.get_bind()
    for name in INDEXES:
        op.drop_index(name, table_name=TABLE)
    for column in COLUMNS:
        # SQLite >= 3.35 drops a column in place (a batch copy would lose the triggers).
        conn.execute(sa.text(f"ALTER TABLE {TABLE} DROP COLUMN {column}"))
    conn.execute(
        sa.text("DELETE FROM version_counters WHERE scope = 'session' OR (scope = 'id' AND key = :key)"),
        {"key": TABLE},
    )
