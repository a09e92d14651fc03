"""Immutability in the database itself, and tamper detection on every read and in `db verify`."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import exc as sa_exc
from sqlalchemy import text
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.errors import UnverifiedRecord
from calibctl.store.engine import make_engine
from calibctl.store.models import IMMUTABLE_TABLES
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.documents import capture_session, check_event, fleet_event, health_report
from tests.store.rig_documents import rig_calibration, rig_definition, rig_session
from tests.store.tamper import forge_activation, patch_stored_bytes

WHO = {"actor": "qa", "station": "st1"}
V1_VIEW = '"version":1,"views":[{"dropped":false,"name":"img01.png","outlier":false,"rms_px":'
ANY_COLUMN = {
    "board_revisions": "name",
    "capture_sessions": "serial",
    "calibration_artifacts": "rms_px",
    "activation_events": "reason",
    "rig_definitions": "payload",
    "rig_sessions": "status",
    "rig_calibrations": "status",
    "rig_activation_events": "reason",
    "check_events": "passed",
    "fleet_events": "kind",
    "health_reports": "rms_px",
}


@pytest.fixture
def filled(db_url: str) -> str:
    with Store.open(db_url) as store:
        store.add_board(measured_board())
        store.add_session(capture_session())
        active = store.add_artifact(calibration(), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(status="rejected"), activate=False, reason="solved", **WHO)
        store.add_check(check_event(active.serial, active.version, active.content_sha256, 1))
        store.add_rig(rig_definition())
        store.add_rig_session(rig_session())
        store.add_rig_calibration(rig_calibration(), activate=True, reason="solved", **WHO)
        store.add_fleet_event(fleet_event("register", serials=[active.serial]))
        store.add_fleet_event(fleet_event("assign", serial=active.serial, version=active.version))
        assert store.add_health_reports([health_report(active.serial)]) == []
    return db_url


def _count(url: str, table: str) -> int:
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            return int(conn.execute(text(f"SELECT count(*) FROM {table}")).scalar_one())
    finally:
        engine.dispose()


@pytest.mark.parametrize("table", sorted(IMMUTABLE_TABLES))
def test_update_and_delete_are_refused_by_the_database_itself(filled: str, table: str):
    before = _count(filled, table)
    column = ANY_COLUMN[table]
    statements = [f"UPDATE {table} SET {column} = {column}", f"DELETE FROM {table}"]
    if filled.startswith("postgresql"):
        statements.append(f"TRUNCATE {table} CASCADE")
    engine = make_engine(filled)
    try:
        for statement in statements:
            with pytest.raises(sa_exc.DBAPIError, match=IMMUTABLE_TABLES[table]), engine.begin() as conn:
                conn.execute(text(statement))
    finally:
        engine.dispose()
    assert before > 0 and _count(filled, table) == before


def test_the_database_refuses_to_activate_a_rejected_artifact(filled: str):
    engine = make_engine(filled)
    insert = text(
        "INSERT INTO activation_events (serial, version, previous_version, kind, actor, station, at, reason) "
        "VALUES ('CAM-0001', 2, 1, 'rollback', 'qa', 'st1', :at, 'raw SQL')"
    )
    try:
        refused = pytest.raises(sa_exc.DBAPIError, match="only an accepted calibration can become active")
        with refused, engine.begin() as conn:
            conn.execute(insert, {"at": "2026-03-11 09:30:00"})
    finally:
        engine.dispose()
    assert _count(filled, "activation_events") == 1


def test_tampered_artifact_bytes_are_caught_on_read_and_by_verify(filled: str):
    # The first view's rms_px 0.284 -> 0.385 in the stored JSON of CAM-0001@1, underneath calibctl.
    patch_stored_bytes(filled, "calibration_artifacts", V1_VIEW + "0.284,", V1_VIEW + "0.385,")
    with Store.open(filled) as store:
        # a read checks the record's chain hash (one sha256 over the stored bytes and columns)
        with pytest.raises(
            UnverifiedRecord, match=r"CAM-0001@1 was changed after it was written \(its chain hash"
        ) as info:
            store.get_artifact("CAM-0001", 1)
        assert info.value.exit_code == 2
        with pytest.raises(UnverifiedRecord, match="CAM-0001@1"):
            store.get_artifact("CAM-0001")  # the active version is the tampered one
        with pytest.raises(UnverifiedRecord, match="CAM-0001@1"):
            store.list_artifacts("CAM-0001")
        assert store.get_artifact("CAM-0001", 2).version == 2  # an intact version still reads
        problems = store.verify().problems
    assert len(problems) == 2
    assert problems[0] == "CAM-0001@1 was changed after it was written (its chain hash no longer matches)"
    assert problems[1].startswith("CAM-0001@1 does not match its recorded sha256")
    result = CliRunner().invoke(app, ["--db", filled, "db", "verify"])
    assert result.exit_code == 1, result.output
    assert "PROBLEM CAM-0001@1 does not match its recorded sha256" in result.stdout
    assert "2 problem(s) in the stored history" in result.stderr


def test_tampered_board_revision_is_caught_on_read_and_by_verify(db_url: str):
    with Store.open(db_url) as store:
        store.add_board(measured_board(name="A17"))
        store.add_board(measured_board(name="B2"))
    patch_stored_bytes(db_url, "board_revisions", '"name":"A17"', '"name":"A18"')
    with Store.open(db_url) as store:
        with pytest.raises(UnverifiedRecord, match=r"board A17@1 does not match its recorded sha256"):
            store.get_board("A17")
        assert store.get_board("B2").name == "B2"
        problems = store.verify().problems
    assert sorted(p.split(" was changed")[0].split(" does not")[0] for p in problems) == [
        "board A17@1",
        "board A17@1",
    ]


def test_tampered_session_is_caught_on_read_and_by_verify(db_url: str):
    with Store.open(db_url) as store:
        store.add_session(capture_session())
    patch_stored_bytes(db_url, "capture_sessions", "[100.25,80.5]", "[100.75,80.5]")  # move one corner
    with Store.open(db_url) as store:
        with pytest.raises(UnverifiedRecord, match="capture session 0123456789ab does not match"):
            store.get_session("0123456789ab")
        problems = store.verify().problems  # the payload hash, and since 0009 the session's chain hash
    assert (
        problems
        == [
            "capture session 0123456789ab was changed after it was written (its chain hash no longer "
            "matches)",
            *[p for p in problems if "does not match its recorded sha256" in p],
        ]
        and len(problems) == 2
    )


def test_forged_activation_of_a_rejected_version_is_caught(filled: str):
    forge_activation(filled, "CAM-0001", 2)
    with Store.open(filled) as store:
        with pytest.raises(
            UnverifiedRecord, match="active version of CAM-0001 is CAM-0001@2, which is not accepted"
        ):
            store.get_artifact("CAM-0001")
        problems = store.verify().problems
    assert problems == [
        "activation event 2 (CAM-0001@2, rollback) has no chain hash: it was inserted outside calibctl",
        "activation event 2 (CAM-0001@2, rollback) activates CAM-0001@2, which is not accepted",
        "activation event 2 (CAM-0001@2, rollback) says None was active before it, but the log says 1",
    ]
    result = CliRunner().invoke(app, ["--db", filled, "db", "verify", "--json"])
    assert result.exit_code == 1
    report = json.loads(result.stdout)
    assert report["ok"] is False and report["problems"] == problems
    assert report["counts"]["artifacts"] == 2


def test_intact_store_verifies_clean(filled: str):
    with Store.open(filled) as store:
        assert store.verify().problems == []
    result = CliRunner().invoke(app, ["--db", filled, "db", "verify"])
    assert result.exit_code == 0, result.output
    assert "verified 2 artifacts, 1 serials, 1 boards, 1 sessions, 1 events, 0 images" in result.stdout
    assert "all intact" in result.stdout
