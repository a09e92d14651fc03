"""image retention: the content-addressed image table, and an index for per-station queries

Revision ID: 0002_image_retention
Revises: 0001_initial
Create Date: 2026-11-22

Images are big and only needed for a while (the corners in capture_sessions are kept forever), so
each stored image file has a row with ``expires_at``; ``Store.prune_images`` deletes expired files
and their rows and nothing else. The index on (station, created_at) serves "what did this station
produce lately", the common audit question on a shared factory store.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002_image_retention"
down_revision: str | Sequence[str] | None = "0001_initial"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "images",
        sa.Column("sha256", sa.String(64), nullable=False),
        sa.Column("size_bytes", sa.BigInteger(), nullable=False),
        sa.Column("stored_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("expires_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("sha256", name="pk_images"),
    )
    op.create_index("ix_images_expires_at", "images", ["expires_at"])
    # A plain CREATE INDEX: no batch copy of calibration_artifacts, so its triggers stay untouched.
    op.create_index(
        "ix_calibration_artifacts_station_created_at", "calibration_artifacts", ["station", "created_at"]
    )


def downgrade() -> None:
    op.drop_index("ix_calibration_artifacts_station_created_at", table_name="calibration_artifacts")
    op.drop_index("ix_images_expires_at", table_name="images")
    op.drop_table("images")
