"""The tamper matrix of tests/store/test_chain_tamper.py, extended to rig versions (hand-eye edges
included), rig activation events and check events (revision 0007): every change someone with write access
makes is named by `db verify` (SQLite with its triggers dropped; PostgreSQL with triggers switched off)."""

from __future__ import annotations

import datetime as dt
import json

import numpy as np
import pytest

from calibctl.artifacts.check import CheckEvent
from calibctl.artifacts.rig import RigCalibration, RigEdge
from calibctl.signing import TrustedKeys, create_key
from calibctl.store import codec
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.documents import check_event
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.store.tamper import rechain, run_underneath
from tests.store.test_chain_tamper import _select, problems_of

WHO = {"actor": "qa", "station": "st1"}
AT = dt.datetime(2026, 11, 23, 9, 0, tzinfo=dt.UTC)


def with_handeye_edge(cal: RigCalibration) -> RigCalibration:
    T = np.eye(4)
    T[2, 3] = 0.1
    edge = RigEdge(
        parent="CAM-0001",
        child="flange",
        T_parent_child=tuple(map(tuple, T.tolist())),
        covariance=(np.eye(6) * 1e-8).tolist(),
        translation_mm=100.0,
        sigma_translation_mm=0.1,
        rotation_deg=0.0,
        sigma_rotation_deg=0.01,
        source="hand-eye",
    )
    return cal.model_copy(update={"edges": [*cal.edges, edge]})


@pytest.fixture
def history(db_url: str) -> str:
    """STEREO-1: v1 accepted, v2 rejected, v3 accepted with a hand-eye edge, then a rollback to 1 (rig events
    1-3); CAM-1 checked twice (checks 1, 2), CAM-2 once (check 3)."""
    with Store.open(db_url) as store:
        store.add_board(measured_board())
        cam1 = store.add_artifact(calibration(serial="CAM-1"), activate=True, reason="solved", **WHO)
        cam2 = store.add_artifact(calibration(serial="CAM-2"), activate=True, reason="solved", **WHO)
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, reason="rig solve", **WHO)
        store.add_rig_calibration(
            rig_calibration(status="rejected"), activate=False, reason="rig solve", **WHO
        )
        store.add_rig_calibration(
            with_handeye_edge(rig_calibration()), activate=True, reason="hand-eye", **WHO
        )
        store.rollback_rig(RIG, 1, reason="v3 drifts", **WHO)
        store.add_check(check_event("CAM-1", 1, cam1.content_sha256, 1))
        store.add_check(check_event("CAM-1", 1, cam1.content_sha256, 2, passed=False))
        store.add_check(check_event("CAM-2", 1, cam2.content_sha256, 3))
        assert store.verify().problems == []
    return db_url


def _reseal_rig(url: str, version: int, change) -> None:  # type: ignore[no-untyped-def]
    """Change a stored rig version and recompute its content_sha256, as a careful forger would."""
    (payload,) = _select(url, f"SELECT payload FROM rig_calibrations WHERE version = {version}")[0]
    forged = change(RigCalibration.model_validate(json.loads(payload))).sealed()
    run_underneath(
        url,
        "UPDATE rig_calibrations SET payload = %s, content_sha256 = %s, status = %s WHERE version = %s",
        params=(codec.canonical_text(forged), forged.content_sha256, forged.status, version),
    )


def test_the_new_streams_are_chained(history: str):
    rows = _select(history, "SELECT version, chain_seq FROM rig_calibrations ORDER BY id")
    assert rows == [(1, 1), (2, 2), (3, 3)]
    assert _select(history, "SELECT serial, chain_seq FROM check_events ORDER BY id") == [
        ("CAM-1", 1),
        ("CAM-1", 2),
        ("CAM-2", 1),
    ]
    assert [r[0] for r in _select(history, "SELECT chain_seq FROM rig_activation_events ORDER BY id")] == [
        1,
        2,
        3,
    ]


def test_rig_version_payload_changed_with_its_hash_recomputed(history: str):
    def longer_baseline(cal: RigCalibration) -> RigCalibration:
        edge = cal.edges[0]
        T = [list(r) for r in edge.T_parent_child]
        T[0][3] *= 1.01
        moved = edge.model_copy(update={"T_parent_child": tuple(map(tuple, T))})
        return cal.model_copy(update={"edges": [moved, *cal.edges[1:]]})

    _reseal_rig(history, 1, longer_baseline)
    assert problems_of(history) == [
        f"rig {RIG}@1 was changed after it was written (its chain hash no longer matches)"
    ]


def test_rig_version_payload_changed_and_the_chain_rewritten(history: str):
    """Without the key the forger can re-chain but not re-sign: in an unsigned store the chain head kept
    elsewhere catches it (here the changed record's hash differs from the head's)."""
    with Store.open(history) as store:
        head = store.verify().head()
    _reseal_rig(history, 2, lambda cal: cal.model_copy(update={"status": "accepted"}))
    rechain(history)
    with Store.open(history) as store:
        assert store.verify().problems == []  # a fully re-chained unsigned store is consistent ...
        problems = store.verify(since=head).problems
    assert any("rewritten or truncated" in p for p in problems)  # ... but not with the head kept elsewhere


def test_hand_eye_edge_deleted_from_its_version(history: str):
    _reseal_rig(
        history,
        3,
        lambda cal: cal.model_copy(update={"edges": [e for e in cal.edges if e.source != "hand-eye"]}),
    )
    assert problems_of(history) == [
        f"rig {RIG}@3 was changed after it was written (its chain hash no longer matches)"
    ]


def test_hand_eye_version_deleted(history: str):
    run_underneath(
        history,
        "DELETE FROM rig_activation_events WHERE version = 3",
        "DELETE FROM rig_calibrations WHERE version = 3",
    )
    problems = problems_of(history)
    assert (
        f"the rig counter of {RIG} is 3 but the highest version stored is 2: the counter or the records "
        "were changed" in problems
    )
    assert any(
        p.startswith(f"rig activation event 3 ({RIG}@1, rollback) is at chain position 3 but 2 was expected")
        for p in problems
    )


def test_rejected_rig_version_deleted(history: str):
    run_underneath(history, "DELETE FROM rig_calibrations WHERE version = 2")
    assert problems_of(history) == [
        f"rig {RIG}@3 is at chain position 3 but 2 was expected: records before it are missing"
    ]


def test_rig_activation_event_deleted(history: str):
    run_underneath(history, "DELETE FROM rig_activation_events WHERE id = 2")
    problems = problems_of(history)
    assert any(
        p.startswith(f"rig activation event 3 ({RIG}@1, rollback) is at chain position 3 but 2 was expected")
        for p in problems
    )


def test_rig_activation_event_forged_by_a_plain_insert(history: str):
    run_underneath(
        history,
        "INSERT INTO rig_activation_events (rig, version, previous_version, kind, actor, station, at, "
        f"reason) VALUES ('{RIG}', 3, 1, 'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'forged')",
    )
    assert problems_of(history) == [
        f"rig activation event 4 ({RIG}@3, rollback) has no chain hash: it was inserted outside calibctl"
    ]


@pytest.mark.parametrize(("table", "first"), [("rig_activation_events", 2), ("check_events", 1)])
def test_events_reordered(history: str, table: str, first: int):
    second = first + 1
    run_underneath(
        history,
        f"UPDATE {table} SET id = 100 WHERE id = {first}",
        f"UPDATE {table} SET id = {first} WHERE id = {second}",
        f"UPDATE {table} SET id = {second} WHERE id = 100",
    )
    assert any("is out of order" in p for p in problems_of(history))


def test_check_event_deleted(history: str):
    run_underneath(history, "DELETE FROM check_events WHERE id = 1")
    problems = problems_of(history)
    assert problems == [
        f"check {2:012x} of CAM-1@1 is at chain position 2 but 1 was expected: records before it are missing"
    ]


def test_last_check_event_of_a_serial_deleted(history: str):
    """A failed check hidden by deleting it: the serial's check counter still counts it."""
    run_underneath(history, "DELETE FROM check_events WHERE id = 2")
    assert problems_of(history) == [
        "the check counter of CAM-1 is 2 but the highest chain_seq stored is 1: the counter or the records "
        "were changed"
    ]


def test_failed_check_turned_passed_with_its_hash_recomputed(history: str):
    (payload,) = _select(history, "SELECT payload FROM check_events WHERE id = 2")[0]
    data = json.loads(payload)
    data["passed"] = True
    forged = codec.canonical_text(CheckEvent.model_validate(data))
    run_underneath(
        history,
        "UPDATE check_events SET payload = %s, payload_sha256 = %s, passed = %s WHERE id = 2",
        params=(forged, codec.sha256_hex(forged.encode()), True),
    )
    assert problems_of(history) == [
        f"check {2:012x} of CAM-1@1 was changed after it was written (its chain hash no longer matches)"
    ]


def test_check_event_inserted_outside_calibctl(history: str):
    (payload, digest) = _select(history, "SELECT payload, payload_sha256 FROM check_events WHERE id = 3")[0]
    run_underneath(
        history,
        "INSERT INTO check_events (check_id, serial, version, passed, at, payload, payload_sha256) "
        "VALUES ('ffffffffffff', 'CAM-2', 1, %s, '2026-11-23 10:00:00', %s, %s)",
        params=(True, payload, digest),
    )
    problems = problems_of(history)
    assert "check ffffffffffff of CAM-2@1 has no chain hash: it was inserted outside calibctl" in problems


def test_0007_chains_the_rows_stored_before_it(history: str):
    from calibctl.store import migrate

    engine = make_engine(history)
    try:
        assert migrate.downgrade(engine, "0006_check_events") == (
            "0016_chain_health_reports",
            "0006_check_events",
        )
        assert migrate.upgrade(engine) == ("0006_check_events", "0016_chain_health_reports")
    finally:
        engine.dispose()
    with Store.open(history) as store:
        audit = store.verify()
        assert audit.problems == [] and audit.records_checked == 15  # the rig definition too (0008)
    assert _select(history, "SELECT serial, chain_seq FROM check_events ORDER BY id") == [
        ("CAM-1", 1),
        ("CAM-1", 2),
        ("CAM-2", 1),
    ]
    run_underneath(history, "DELETE FROM check_events WHERE id = 2")  # the backfilled counters count them
    assert problems_of(history) == [
        "the check counter of CAM-1 is 2 but the highest chain_seq stored is 1: the counter or the records "
        "were changed"
    ]


def _signed_history(url: str, key_path) -> TrustedKeys:  # type: ignore[no-untyped-def]
    signer = create_key(key_path)
    with Store.open(url, signer=signer) as store:
        art = store.add_artifact(calibration(serial="CAM-1"), activate=True, reason="solved", **WHO)
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, reason="rig solve", **WHO)
        store.add_rig_calibration(
            with_handeye_edge(rig_calibration()), activate=True, reason="hand-eye", **WHO
        )
        store.add_check(check_event("CAM-1", 1, art.content_sha256, 1, passed=False))
    return TrustedKeys({signer.key_id: signer.public})


def test_rig_versions_rig_events_and_checks_are_signed(db_url: str, tmp_path):  # type: ignore[no-untyped-def]
    trusted = _signed_history(db_url, tmp_path / "k.pem")
    with Store.open(db_url) as reader:
        audit = reader.verify(trusted, require_signature=True)
    assert audit.problems == [] and audit.unsigned == 0
    # camera artifact and event, rig versions, rig events, check, rig definition
    assert audit.signatures_checked == 2 + 2 + 2 + 1 + 1


def test_a_rechained_check_forgery_is_caught_by_the_signature(db_url: str, tmp_path):  # type: ignore[no-untyped-def]
    trusted = _signed_history(db_url, tmp_path / "k.pem")
    (payload,) = _select(db_url, "SELECT payload FROM check_events")[0]
    forged = codec.canonical_text(CheckEvent.model_validate({**json.loads(payload), "passed": True}))
    run_underneath(
        db_url,
        "UPDATE check_events SET payload = %s, payload_sha256 = %s, passed = %s",
        params=(forged, codec.sha256_hex(forged.encode()), True),
    )
    rechain(db_url)
    with Store.open(db_url) as reader:
        assert reader.verify().problems == []  # self-consistent without the key ...
        problems = reader.verify(trusted).problems
    assert len(problems) == 1 and problems[0].startswith(f"check {1:012x} of CAM-1@1 has a signature by key")


def test_an_unsigned_rig_version_after_signed_ones_is_a_finding(db_url: str, tmp_path):  # type: ignore[no-untyped-def]
    _signed_history(db_url, tmp_path / "k.pem")
    with Store.open(db_url) as unsigned_writer:
        unsigned_writer.add_rig_calibration(rig_calibration(), activate=False, reason="x", **WHO)
        problems = unsigned_writer.verify().problems
    assert problems == [f"rig {RIG}@3 is not signed, but records before it in its chain are"]


def test_a_head_printed_before_0007_checks_the_new_streams_in_full(history: str):
    from calibctl.store import audit as audit_module

    with Store.open(history) as store:
        full = store.verify()
    old = ("artifact", "board", "event")  # the streams a head named before revision 0007
    ids = ".".join(str(full.last_ids[name]) for name in old)
    head = f"{audit_module.HEAD_PREFIX}:{ids}:{audit_module._digest({n: full.heads[n] for n in old})}"
    with Store.open(history) as store:
        resumed = store.verify(since=head)
    # rig versions, rig events, checks, the rig definition (0008)
    assert resumed.problems == [] and resumed.records_checked == 3 + 3 + 3 + 1
    run_underneath(history, "DELETE FROM check_events WHERE id = 1")
    with Store.open(history) as store:
        assert store.verify(since=head).problems == [
            f"check {2:012x} of CAM-1@1 is at chain position 2 but 1 was expected: records before it are "
            "missing"
        ]


def test_a_forged_rig_event_activating_a_rejected_version_is_named(history: str):
    run_underneath(
        history,
        "INSERT INTO rig_activation_events (rig, version, previous_version, kind, actor, station, at, "
        f"reason) VALUES ('{RIG}', 2, 3, 'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'forged')",
    )
    assert problems_of(history) == [
        f"rig activation event 4 ({RIG}@2, rollback) has no chain hash: it was inserted outside calibctl",
        f"rig activation event 4 ({RIG}@2, rollback) activates rig {RIG}@2, which is not accepted",
        f"rig activation event 4 ({RIG}@2, rollback) says 3 was active before it, but the log says 1",
    ]


def test_since_head_checks_new_events_against_what_was_active_at_the_head(history: str):
    """--since reads only each serial's last event before HEAD, and still knows what was active there."""
    with Store.open(history) as store:
        head = store.verify().head()
        store.add_artifact(calibration(serial="CAM-1", fx=802.0), activate=True, reason="solved", **WHO)
        assert store.verify(since=head).problems == []
    run_underneath(
        history,
        "INSERT INTO activation_events (serial, version, previous_version, kind, actor, station, "
        "at, reason) VALUES ('CAM-2', 1, 7, 'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'forged')",
    )
    with Store.open(history) as store:
        problems = store.verify(since=head).problems
    assert problems == [
        "activation event 4 (CAM-2@1, rollback) has no chain hash: it was inserted outside calibctl",
        "activation event 4 (CAM-2@1, rollback) says 7 was active before it, but the log says 1",
    ]
