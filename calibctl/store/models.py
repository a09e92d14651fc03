"""Tables of the store (SQLAlchemy 2.0 typed models).

Each document is kept as the canonical JSON the contract hashes (``payload``) plus its sha256, so a
read can prove the bytes are the ones that were written; the other columns are copies of payload
fields that queries filter and sort on. Board revisions, capture sessions, calibration artifacts
and activation events are immutable: triggers created by the migrations refuse UPDATE and DELETE on
them in the database itself (see migrations/versions/*_0001_*). ``version_counters`` is the one
mutable table: the per-serial (and per-board) counter that hands out versions under concurrency.

These models must match the migrations; tests/store/test_migrations.py compares them.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from typing import Any

from sqlalchemy import (
    BigInteger,
    Boolean,
    CheckConstraint,
    DateTime,
    Double,
    ForeignKeyConstraint,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.engine import Dialect
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column
from sqlalchemy.types import TypeDecorator

from calibctl.store.unreadable import unreadable_datetime

NAMING_CONVENTION = {
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_N_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

SERIAL_LEN = 128
BOARD_REF_LEN = 80
SHA256_LEN = 64
SESSION_ID_LEN = 12


class UtcDateTime(TypeDecorator[dt.datetime]):
    """Timezone-aware UTC datetimes on both backends (SQLite stores naive UTC text)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: dt.datetime | None, dialect: Dialect) -> dt.datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError("the store only keeps timezone-aware datetimes")
        value = value.astimezone(dt.UTC)
        return value if dialect.name == "postgresql" else value.replace(tzinfo=None)

    def process_result_value(self, value: dt.datetime | None, dialect: Dialect) -> dt.datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=dt.UTC) if value.tzinfo is None else value.astimezone(dt.UTC)

    def result_processor(self, dialect: Dialect, coltype: object) -> Callable[[Any], Any] | None:
        # SQLite keeps text: a value edited outside calibctl ('garbage', a number) fails in SQLAlchemy's own
        # parser before process_result_value; it is a tampered record (exit 2), never a traceback.
        process = super().result_processor(dialect, coltype)
        if process is None:
            return None

        def checked(value: Any) -> Any:
            try:
                return process(value)
            except (TypeError, ValueError) as exc:
                raise unreadable_datetime(value) from exc

        return checked


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)


class ChainColumns:
    """The hash chain and signature of an immutable record (revision 0005; see ``store.chain``).

    Nullable only because rows are written before 0005 are chained by its migration; ``db verify``
    reports any row without a chain hash as inserted outside calibctl."""

    chain_seq: Mapped[int | None] = mapped_column(Integer, nullable=True)
    chain_prev: Mapped[str | None] = mapped_column(String(SHA256_LEN), nullable=True)
    chain_hash: Mapped[str | None] = mapped_column(String(SHA256_LEN), nullable=True)
    signature: Mapped[str | None] = mapped_column(Text, nullable=True)
    key_id: Mapped[str | None] = mapped_column(String(SHA256_LEN), nullable=True)


class BoardRow(ChainColumns, Base):
    """One immutable board revision."""

    __tablename__ = "board_revisions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64))
    revision: Mapped[int] = mapped_column(Integer)
    kind: Mapped[str] = mapped_column(String(16))
    measurement_status: Mapped[str] = mapped_column(String(16))
    square_size_m: Mapped[float] = mapped_column(Double)
    created_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (
        UniqueConstraint("name", "revision"),
        CheckConstraint("revision >= 1", name="revision_positive"),
        Index(None, "name", "chain_seq", unique=True),
    )


class SessionRow(ChainColumns, Base):
    """One immutable capture session (corners are kept forever; images only for the retention time).

    Chained since revision 0009, one stream per serial (``chain.STREAMS["session"]``). ``id`` is given by
    calibctl (the store-wide ('id', 'capture_sessions') counter, after the serial's session counter lock);
    the session id stays the primary key."""

    __tablename__ = "capture_sessions"

    session_id: Mapped[str] = mapped_column(String(SESSION_ID_LEN), primary_key=True)
    id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    serial: Mapped[str] = mapped_column(String(SERIAL_LEN))
    board_ref: Mapped[str] = mapped_column(String(BOARD_REF_LEN))
    status: Mapped[str] = mapped_column(String(16))
    station: Mapped[str] = mapped_column(Text)
    operator: Mapped[str] = mapped_column(Text)
    started_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    finished_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (
        Index(None, "serial", "started_at"),
        Index(None, "id", unique=True),
        Index(None, "serial", "chain_seq", unique=True),
    )


class ArtifactRow(ChainColumns, Base):
    """One immutable calibration version of one serial."""

    __tablename__ = "calibration_artifacts"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(SERIAL_LEN))
    version: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16))
    rms_px: Mapped[float] = mapped_column(Double)
    sigma_fx_px: Mapped[float | None] = mapped_column(Double, nullable=True)
    station: Mapped[str] = mapped_column(Text)
    operator: Mapped[str] = mapped_column(Text)
    created_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    board_ref: Mapped[str] = mapped_column(String(BOARD_REF_LEN))
    session_id: Mapped[str | None] = mapped_column(String(SESSION_ID_LEN), nullable=True)
    stored_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    content_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (
        UniqueConstraint("serial", "version"),
        CheckConstraint("version >= 1", name="version_positive"),
        CheckConstraint("status IN ('accepted', 'rejected')", name="status_known"),
        Index(None, "status"),
        Index(None, "station", "created_at"),
        Index(None, "serial", "chain_seq", unique=True),
    )


class ActivationColumns:
    """One move of an active version (activate or rollback): who, where, when and why. A serial's and a
    rig's activation events share them; only the subject column and its foreign key differ."""

    version: Mapped[int] = mapped_column(Integer)
    previous_version: Mapped[int | None] = mapped_column(Integer, nullable=True)
    kind: Mapped[str] = mapped_column(String(16))
    actor: Mapped[str] = mapped_column(Text)
    station: Mapped[str] = mapped_column(Text)
    at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    reason: Mapped[str] = mapped_column(Text)


class EventRow(ActivationColumns, ChainColumns, Base):
    """One append-only move of a serial's active version."""

    __tablename__ = "activation_events"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(SERIAL_LEN))

    __table_args__ = (
        ForeignKeyConstraint(
            ["serial", "version"], ["calibration_artifacts.serial", "calibration_artifacts.version"]
        ),
        CheckConstraint("kind IN ('activate', 'rollback')", name="kind_known"),
        Index(None, "serial", "id"),
        Index(None, "chain_seq", unique=True),
    )


class CounterRow(Base):
    """The last version handed out per (scope, key): ('artifact', serial) and ('board', name)."""

    __tablename__ = "version_counters"

    scope: Mapped[str] = mapped_column(String(16), primary_key=True)
    key: Mapped[str] = mapped_column(String(SERIAL_LEN), primary_key=True)
    last_value: Mapped[int] = mapped_column(Integer)


class ImageRow(Base):
    """A content-addressed image file beside the database, kept until ``expires_at`` (revision 0002)."""

    __tablename__ = "images"

    sha256: Mapped[str] = mapped_column(String(SHA256_LEN), primary_key=True)
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    stored_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    expires_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)

    __table_args__ = (Index(None, "expires_at"),)


class RigRow(ChainColumns, Base):
    """One registered rig (revision 0003): members, root and design values; immutable.

    Chained since revision 0008 in one stream for the store (``chain.STREAMS["rig_definition"]``).
    ``id`` is its position in that stream, given by calibctl under the stream's counter lock (the name
    stays the primary key the rig tables refer to); nullable only because the migration adds it."""

    __tablename__ = "rig_definitions"

    name: Mapped[str] = mapped_column(String(SERIAL_LEN), primary_key=True)
    id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (Index(None, "id", unique=True), Index(None, "chain_seq", unique=True))


class RigSessionRow(Base):
    """One immutable rig capture (revision 0003): per-camera session ids and the frame pairing."""

    __tablename__ = "rig_sessions"

    rig_session_id: Mapped[str] = mapped_column(String(SESSION_ID_LEN), primary_key=True)
    rig: Mapped[str] = mapped_column(String(SERIAL_LEN))
    status: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (Index(None, "rig", "created_at"),)


class RigCalibrationRow(ChainColumns, Base):
    """One immutable calibration version of one rig (revision 0003; chained per rig since 0007)."""

    __tablename__ = "rig_calibrations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rig: Mapped[str] = mapped_column(String(SERIAL_LEN))
    version: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    content_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (
        UniqueConstraint("rig", "version"),
        CheckConstraint("version >= 1", name="version_positive"),
        CheckConstraint("status IN ('accepted', 'rejected')", name="status_known"),
        Index(None, "rig", "chain_seq", unique=True),
    )


class RigEventRow(ActivationColumns, ChainColumns, Base):
    """One append-only move of a rig's active version (revision 0003; one chain for the store since 0007)."""

    __tablename__ = "rig_activation_events"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rig: Mapped[str] = mapped_column(String(SERIAL_LEN))

    __table_args__ = (
        ForeignKeyConstraint(["rig", "version"], ["rig_calibrations.rig", "rig_calibrations.version"]),
        CheckConstraint("kind IN ('activate', 'rollback')", name="kind_known"),
        Index(None, "rig", "id"),
        Index(None, "chain_seq", unique=True),
    )


class CheckEventRow(ChainColumns, Base):
    """One re-test of one calibration version (revision 0006; chained per serial since 0007)."""

    __tablename__ = "check_events"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    check_id: Mapped[str] = mapped_column(String(12), unique=True)
    serial: Mapped[str] = mapped_column(String(SERIAL_LEN))
    version: Mapped[int] = mapped_column(Integer)
    passed: Mapped[bool] = mapped_column(Boolean)
    at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (
        ForeignKeyConstraint(
            ["serial", "version"], ["calibration_artifacts.serial", "calibration_artifacts.version"]
        ),
        Index(None, "serial", "id"),
        Index(None, "serial", "chain_seq", unique=True),
    )


class FleetEventRow(ChainColumns, Base):
    """One step of the fleet's log (revision 0010_fleet_diff25): a robot registered or assigned a version.

    One chained stream for the store (``chain.STREAMS["fleet"]``); ``id`` is the position in it, given under
    the stream's counter lock."""

    __tablename__ = "fleet_events"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    subject: Mapped[str] = mapped_column(String(SERIAL_LEN))  # the robot, or the rollout of the rollout kinds
    kind: Mapped[str] = mapped_column(String(16))
    at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (Index(None, "subject", "id"), Index(None, "chain_seq", unique=True))


class FleetCheckpointRow(Base):
    """The fleet log replayed up to event ``position`` (revision 0015_checkpoints_fleet_ckpt): derived data,
    never the source of truth. ``chain_hash`` is event ``position``'s, so a checkpoint of a log that was
    rewritten is ignored; ``state`` is ``fleet_ledger.to_state``'s JSON with its sha256. Not immutable: old
    ones are pruned."""

    __tablename__ = "fleet_checkpoints"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    position: Mapped[int] = mapped_column(Integer, unique=True)
    chain_hash: Mapped[str] = mapped_column(String(SHA256_LEN))
    format: Mapped[int] = mapped_column(Integer)
    written_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    state: Mapped[str] = mapped_column(Text)
    state_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))
    signature: Mapped[str | None] = mapped_column(
        Text, nullable=True
    )  # with a station key (store.fleet_checkpoints)
    key_id: Mapped[str | None] = mapped_column(String(SHA256_LEN), nullable=True)


class HealthReportRow(ChainColumns, Base):
    """One health report a robot sent (revision 0011_health_reports_health25): the numbers as columns, the
    document's canonical JSON and its sha256. Append-only; chained since 0016 in one stream for the store
    (``chain.STREAMS["health"]``): a promote decides on these."""

    __tablename__ = "health_reports"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    source_id: Mapped[str] = mapped_column(String(SERIAL_LEN), unique=True)
    serial: Mapped[str] = mapped_column(String(SERIAL_LEN))
    robot: Mapped[str] = mapped_column(String(SERIAL_LEN))
    kind: Mapped[str] = mapped_column(String(16))
    at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    rms_px: Mapped[float | None] = mapped_column(Double, nullable=True)
    verdict: Mapped[str | None] = mapped_column(String(32), nullable=True)
    ratio: Mapped[float | None] = mapped_column(Double, nullable=True)
    sigma: Mapped[float | None] = mapped_column(Double, nullable=True)
    td_ms: Mapped[float | None] = mapped_column(Double, nullable=True)
    sigma_ms: Mapped[float | None] = mapped_column(Double, nullable=True)
    temperature_c: Mapped[float | None] = mapped_column(Double, nullable=True)
    ingested_at: Mapped[dt.datetime] = mapped_column(UtcDateTime)
    payload: Mapped[str] = mapped_column(Text)
    payload_sha256: Mapped[str] = mapped_column(String(SHA256_LEN))

    __table_args__ = (
        Index(None, "serial", "kind", "at"),
        Index(None, "kind", "at", "serial", "rms_px"),  # 0014: the per-camera spread's window
        Index(None, "chain_seq", unique=True),  # 0016
    )


IMMUTABLE_TABLES = {
    "board_revisions": "board revisions are immutable",
    "capture_sessions": "capture sessions are immutable",
    "calibration_artifacts": "calibration artifacts are immutable",
    "activation_events": "activation events are append-only",
    "rig_definitions": "rig definitions are immutable",
    "rig_sessions": "rig sessions are immutable",
    "rig_calibrations": "rig calibrations are immutable",
    "rig_activation_events": "rig activation events are append-only",
    "check_events": "check events are append-only",
    "fleet_events": "fleet events are append-only",
    "health_reports": "health reports are append-only",
}
"""Table -> the message its UPDATE/DELETE trigger raises (the migrations create the triggers)."""
