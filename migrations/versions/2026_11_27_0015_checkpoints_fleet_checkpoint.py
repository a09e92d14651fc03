"""fleet_checkpoints: the fleet log replayed up to an event, so `fleet status` replays only the events after
it

Revision ID: 0015_checkpoints_fleet_ckpt
Revises: 0014_health_window_fleet25
Create Date: 2026-11-27

Derived data, never the source of truth (``store/fleet_checkpoints.py``): each row is the replayed state at
log position ``position`` with that event's chain hash, checked on use and by ``db verify``. No immutability
triggers:
a write prunes all but the newest few, and deleting every row only costs the next read a full replay. With a
station key a checkpoint is signed (``signature``, ``key_id``): a store with keys uses only checkpoints signed
by a trusted key.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0015_checkpoints_fleet_ckpt"
down_revision: str | Sequence[str] | None = "0014_health_window_fleet25"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "fleet_checkpoints"


def upgrade() -> None:
    op.create_table(
        TABLE,
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("chain_hash", sa.String(64), nullable=False),
        sa.Column("format", sa.Integer(), nullable=False),
        sa.Column("written_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("state", sa.Text(), nullable=False),
        sa.Column("state_sha256", sa.String(64), nullable=False),
        sa.Column("signature", sa.Text(), nullable=True),
        sa.Column("key_id", sa.String(64), nullable=True),
        sa.PrimaryKeyConstraint("id", name="pk_fleet_checkpoints"),
        sa.UniqueConstraint("position", name="uq_fleet_checkpoints_position"),
    )


def downgrade() -> None:
    op.drop_table(TABLE)
