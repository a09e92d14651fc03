"""Rigs in the store, on SQLite and PostgreSQL: versions per rig, activation, rollback, tamper checks."""

from __future__ import annotations

import pytest
from sqlalchemy import text

from calibctl.errors import AlreadyExistsError, NotFoundError, UnverifiedRecord, UsageError
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.store.rig_documents import RIG, rig_calibration, rig_definition, rig_session

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


def test_rig_documents_round_trip(db_url: str):
    with Store.open(db_url) as store:
        assert store.add_rig(rig_definition()) == store.get_rig(RIG)
        store.add_rig_session(rig_session())
        assert store.get_rig_session(RIG) == rig_session()
        first = store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
        second = store.add_rig_calibration(rig_calibration(baseline_m=0.0751), activate=True, **WHO)
        assert (first.version, second.version) == (1, 2)
        assert first.content_sha256 == first.computed_sha256()
        assert store.get_rig_calibration(RIG) == second
        assert store.get_rig_calibration(RIG, 1) == first
        assert [c.version for c in store.list_rig_calibrations(RIG)] == [1, 2]


def test_rig_names_are_registered_once_and_unknown_ones_are_named(db_url: str):
    with Store.open(db_url) as store:
        store.add_rig(rig_definition())
        with pytest.raises(AlreadyExistsError, match="already registered"):
            store.add_rig(rig_definition())
        with pytest.raises(NotFoundError, match="unknown rig 'NOPE'; known: STEREO-1"):
            store.get_rig("NOPE")
        with pytest.raises(NotFoundError, match="has no calibration yet"):
            store.get_rig_calibration(RIG)
        with pytest.raises(NotFoundError, match="no an accepted rig session"):
            store.get_rig_session(RIG)


def test_rollback_and_rejected_versions(db_url: str):
    with Store.open(db_url) as store:
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
        store.add_rig_calibration(rig_calibration(status="rejected"), activate=False, **WHO)
        store.add_rig_calibration(rig_calibration(baseline_m=0.076), activate=True, **WHO)
        with pytest.raises(UsageError, match="rejected calibration can never become active"):
            store.add_rig_calibration(rig_calibration(status="rejected"), activate=True, **WHO)
        with pytest.raises(UsageError, match="@2 is rejected"):
            store.rollback_rig(RIG, 2, reason="try", actor="qa", station="st1")
        event = store.rollback_rig(RIG, 1, reason="drifted", actor="qa", station="st1")
        assert (event.version, event.previous_version, event.kind) == (1, 3, "rollback")
        assert store.active_rig_version(RIG) == 1
        assert store.rollback_rig(RIG, 1, reason="again", actor="qa", station="st1") is None  # already active
        assert [e.version for e in store.rig_events(RIG)] == [1, 3, 1]


def test_a_rig_without_an_active_version_says_what_to_do(db_url: str):
    with Store.open(db_url) as store:
        store.add_rig_calibration(rig_calibration(status="rejected"), activate=False, **WHO)
        with pytest.raises(
            NotFoundError, match=rf"rig {RIG} has no active version; versions: 1 \(rejected\)"
        ) as none:
            store.get_rig_calibration(RIG)
        # nothing accepted to roll back to: the hint must not propose a rollback
        assert none.value.hint is not None and "roll back" not in none.value.hint
        assert (
            f"solve the rig again (`calibctl rig solve {RIG}`" in none.value.hint
            and none.value.exit_code == 2
        )
        store.add_rig_calibration(rig_calibration(), activate=False, **WHO)  # accepted, --no-activate
        with pytest.raises(NotFoundError, match=r"versions: 1 \(rejected\), 2 \(accepted\)") as one:
            store.get_rig_calibration(RIG)
        assert one.value.hint == f"ask for a version ({RIG}@N) or roll back to an accepted one"


def test_the_database_refuses_to_activate_a_rejected_rig_version(db_url: str):
    with Store.open(db_url) as store:
        store.add_rig_calibration(rig_calibration(status="rejected"), activate=False, **WHO)
    engine = make_engine(db_url)
    try:
        with (
            pytest.raises(Exception, match="only an accepted rig calibration can become active"),
            engine.begin() as conn,
        ):
            conn.execute(
                text(
                    "INSERT INTO rig_activation_events (rig, version, kind, actor, station, at, reason) "
                    "VALUES ('STEREO-1', 1, 'activate', 'x', 'y', CURRENT_TIMESTAMP, 'forged')"
                )
            )
    finally:
        engine.dispose()


def test_tampered_rig_bytes_are_caught_on_read(db_url: str):
    with Store.open(db_url) as store:
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
    engine = make_engine(db_url)
    try:
        with engine.begin() as conn:
            if db_url.startswith("postgresql"):
                conn.execute(text("ALTER TABLE rig_calibrations DISABLE TRIGGER USER"))
                conn.execute(text("UPDATE rig_calibrations SET payload = replace(payload, '75.0', '76.0')"))
                conn.execute(text("ALTER TABLE rig_calibrations ENABLE TRIGGER USER"))
            else:
                conn.execute(text("DROP TRIGGER trg_rig_calibrations_no_update"))
                conn.execute(text("UPDATE rig_calibrations SET payload = replace(payload, '75.0', '76.0')"))
    finally:
        engine.dispose()
    with Store.open(db_url) as store, pytest.raises(UnverifiedRecord, match="rig STEREO-1@1 does not match"):
        store.get_rig_calibration(RIG)


def test_0003_downgrades_with_rig_rows_in_it_and_upgrades_again(db_url: str):
    from sqlalchemy import inspect

    from calibctl.store import migrate

    with Store.open(db_url) as store:
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
    engine = make_engine(db_url)
    try:
        assert migrate.downgrade(engine, "0002_image_retention") == (
            migrate.head_revision(),
            "0002_image_retention",
        )
        assert "rig_calibrations" not in inspect(engine).get_table_names()
        assert migrate.upgrade(engine) == ("0002_image_retention", migrate.head_revision())
    finally:
        engine.dispose()
    with Store.open(db_url) as store:
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
        # the version counter outlives the downgrade: a rig version number is never handed out twice
        assert store.get_rig_calibration(RIG).version == 2
    engine = make_engine(db_url)
    try:
        with pytest.raises(Exception, match="rig calibrations are immutable"), engine.begin() as conn:
            conn.execute(text("DELETE FROM rig_calibrations"))
    finally:
        engine.dispose()
