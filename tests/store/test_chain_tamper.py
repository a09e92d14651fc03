"""The tamper matrix: every change someone with write access to the database can make is
named by `db verify` (SQLite with its triggers dropped; PostgreSQL with triggers switched off)."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import text
from typer.testing import CliRunner

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.cli.main import app
from calibctl.store import codec
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.tamper import run_underneath

WHO = {"actor": "qa", "station": "st1"}


@pytest.fixture
def history(db_url: str) -> str:
    """CAM-1: v1 accepted, v2 rejected, v3 accepted; CAM-2: v1. Events 1-4, the last a rollback of CAM-1 to
    1."""
    with Store.open(db_url) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(serial="CAM-1"), activate=True, reason="solved", **WHO)
        store.add_artifact(
            calibration(serial="CAM-1", status="rejected"), activate=False, reason="solved", **WHO
        )
        store.add_artifact(calibration(serial="CAM-1", fx=801.0), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(serial="CAM-2"), activate=True, reason="solved", **WHO)
        store.rollback("CAM-1", 1, reason="v3 drifts", **WHO)
        assert store.verify().problems == []
    return db_url


def problems_of(url: str) -> list[str]:
    with Store.open(url) as store:
        return store.verify().problems


def _select(url: str, sql: str) -> list[tuple]:
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            return [tuple(r) for r in conn.execute(text(sql))]
    finally:
        engine.dispose()


def _reseal_artifact(url: str, serial: str, version: int, **changes: object) -> None:
    """Change fields of a stored artifact and recompute its content_sha256, as a careful forger would."""
    (payload,) = _select(
        url, f"SELECT payload FROM calibration_artifacts WHERE serial = '{serial}' AND version = {version}"
    )[0]
    data = json.loads(payload)
    data.update(changes)
    forged = CalibrationArtifact.model_validate(data).sealed()
    run_underneath(
        url,
        "UPDATE calibration_artifacts SET payload = %s, content_sha256 = %s, status = %s WHERE serial = %s "
        "AND version = %s",
        params=(codec.canonical_text(forged), forged.content_sha256, forged.status, serial, version),
    )


def test_payload_changed_with_its_content_hash_recomputed(history: str):
    (payload,) = _select(
        history, "SELECT payload FROM calibration_artifacts WHERE serial = 'CAM-1' AND version = 1"
    )[0]
    k = json.loads(payload)["camera_matrix"]
    k[0][0] += 5.0  # fx + 5 px
    _reseal_artifact(history, "CAM-1", 1, camera_matrix=k)
    assert problems_of(history) == [
        "CAM-1@1 was changed after it was written (its chain hash no longer matches)"
    ]


def test_rejected_version_turned_accepted_with_a_forged_rollback(history: str):
    _reseal_artifact(history, "CAM-1", 2, status="accepted")
    run_underneath(
        history,
        "INSERT INTO activation_events (serial, version, previous_version, kind, actor, station, at, reason) "
        "VALUES ('CAM-1', 2, 1, 'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'looks fine')",
    )
    problems = problems_of(history)
    assert "CAM-1@2 was changed after it was written (its chain hash no longer matches)" in problems
    assert any(p.startswith("activation event 5 (CAM-1@2, rollback) has no chain hash") for p in problems)


def test_board_square_size_scaled_with_its_hash_recomputed(history: str):
    (payload,) = _select(history, "SELECT payload FROM board_revisions WHERE name = 'A17'")[0]
    data = json.loads(payload)
    data["measurement"]["square_size_m"] *= 1.01
    forged = codec.canonical_text(BoardRevision.model_validate(data))
    digest = codec.sha256_hex(forged.encode())
    run_underneath(
        history,
        "UPDATE board_revisions SET payload = %s, payload_sha256 = %s, square_size_m = square_size_m * 1.01",
        params=(forged, digest),
    )
    assert problems_of(history) == [
        "board A17@1 was changed after it was written (its chain hash no longer matches)"
    ]


def test_deleted_activation_event(history: str):
    run_underneath(history, "DELETE FROM activation_events WHERE id = 2")
    problems = problems_of(history)
    assert any(
        p.startswith("activation event 3 (CAM-2@1, activate) is at chain position 3 but 2 was expected")
        for p in problems
    )


def test_deleted_last_activation_event(history: str):
    run_underneath(history, "DELETE FROM activation_events WHERE id = 4")
    assert problems_of(history) == [
        "the chain counter of event is 4 but the highest chain_seq stored is 3: the counter or the records "
        "were changed"
    ]


def test_reordered_events(history: str):
    run_underneath(
        history,
        "UPDATE activation_events SET id = 100 WHERE id = 2",
        "UPDATE activation_events SET id = 2 WHERE id = 3",
        "UPDATE activation_events SET id = 3 WHERE id = 100",
    )
    problems = problems_of(history)
    assert any("is out of order" in p for p in problems)


def test_forged_rollback_by_a_plain_insert(history: str):
    run_underneath(
        history,
        "INSERT INTO activation_events (serial, version, previous_version, kind, actor, station, at, reason) "
        "VALUES ('CAM-1', 3, 1, 'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'forged')",
    )
    assert problems_of(history) == [
        "activation event 5 (CAM-1@3, rollback) has no chain hash: it was inserted outside calibctl"
    ]


def test_actor_reason_and_time_rewritten_on_every_event(history: str):
    run_underneath(
        history,
        "UPDATE activation_events SET actor = 'mallory', reason = 'routine', at = '2026-01-01 00:00:00'",
    )
    problems = problems_of(history)
    assert len(problems) == 4 and all("was changed after it was written" in p for p in problems)


@pytest.mark.parametrize("with_events", [False, True])
def test_deleted_artifact_row(history: str, with_events: bool):
    statements = ["DELETE FROM calibration_artifacts WHERE serial = 'CAM-1' AND version = 1"]
    if with_events:
        statements.insert(0, "DELETE FROM activation_events WHERE serial = 'CAM-1' AND version = 1")
    run_underneath(history, *statements)
    problems = problems_of(history)
    assert any(p.startswith("CAM-1@2 is at chain position 2 but 1 was expected") for p in problems)


def test_deleted_rejected_version(history: str):
    run_underneath(history, "DELETE FROM calibration_artifacts WHERE serial = 'CAM-1' AND version = 2")
    assert problems_of(history) == [
        "CAM-1@3 is at chain position 3 but 2 was expected: records before it are missing"
    ]


def test_deleted_last_version(history: str):
    run_underneath(history, "DELETE FROM calibration_artifacts WHERE serial = 'CAM-2'")
    # its activation event names it and the event log no longer adds up
    assert any("names CAM-2@1, which is not stored" in p for p in problems_of(history))


def test_version_counter_lowered(history: str):
    run_underneath(
        history, "UPDATE version_counters SET last_value = 1 WHERE scope = 'artifact' AND key = 'CAM-1'"
    )
    assert problems_of(history) == [
        "the artifact counter of CAM-1 is 1 but the highest version stored is 3: the counter or the "
        "records were changed"
    ]


def test_station_and_operator_columns_changed(history: str):
    run_underneath(
        history,
        "UPDATE calibration_artifacts SET station = 'line9', operator = 'nobody' WHERE serial = 'CAM-2'",
    )
    assert problems_of(history) == [
        "CAM-2@1 was changed after it was written (its chain hash no longer matches)"
    ]


def test_cli_names_the_record_and_exits_1(history: str):
    run_underneath(history, "UPDATE activation_events SET reason = 'routine' WHERE id = 4")
    result = CliRunner().invoke(app, ["--db", history, "db", "verify"])
    assert result.exit_code == 1, result.output
    assert "PROBLEM activation event 4 (CAM-1@1, rollback) was changed after it was written" in result.stdout
    assert "1 problem(s) in the stored history" in result.stderr
