"""health_reports: an index for the per-camera spread over a recent window

Revision ID: 0014_health_window_fleet25
Revises: 0011_health_reports_health25
Create Date: 2026-11-27

``fleet trends`` compares a serial's mean check RMS with every other serial's over the last 30 days of
reports.
At 730k reports the former whole-table aggregate took 0.9 s on PostgreSQL (benchmarks/results/fleet_scale.md);
this index (kind, at, serial, rms_px) serves the window's rows without touching the table.
"""

from __future__ import annotations

from collections.abc import Sequence

from alembic import op

revision: str = "0014_health_window_fleet25"
down_revision: str | Sequence[str] | None = "0011_health_reports_health25"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

INDEX = "ix_health_reports_kind_at_serial_rms_px"


def upgrade() -> None:
    op.create_index(INDEX, "health_reports", ["kind", "at", "serial", "rms_px"])


def downgrade() -> None:
    op.drop_index(INDEX, table_name="health_reports")
