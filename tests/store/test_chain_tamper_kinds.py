"""Every read verifies what it serves, for every record kind, with or without keys: board revisions, rig
versions (their LiDAR and hand-eye edges included) and the fleet log are refused by name when their chain hash
no longer matches (an edit with only the content or payload hash recomputed), and, with keys, when a careful
forger recomputed every chain hash too (only the signature shows it). Nothing refused is used by a write."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.common import canonical_json_bytes, sha256_hex
from calibctl.artifacts.fleet import FleetEvent
from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.errors import UnverifiedRecord
from calibctl.signing import Signer, create_key
from calibctl.store.repository import Store
from calibctl.workflows.lidar import rig_lidar
from tests.artifacts.factories import FIXED_TIME, calibration, measured_board
from tests.store.documents import fleet_event
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.store.tamper import rechain, run_underneath
from tests.store.test_chain_tamper import _select
from tests.store.test_chain_tamper_rigs_checks import _reseal_rig, with_handeye_edge
from tests.workflows.lidar.test_rig_lidar_carry import _lidar

WHO = {"actor": "qa", "station": "st1"}
runner = CliRunner()


def _rewrite(url: str, table: str, where: str, change: Callable[[dict[str, Any]], None]) -> None:
    """Edit the payload of the one row of ``table`` matching ``where`` and recompute its payload_sha256 (its
    chain hash left as it was), as someone with write access to the database would."""
    rows = _select(url, f"SELECT id, payload FROM {table} WHERE {where}")
    assert len(rows) == 1, rows
    row_id, payload = rows[0]
    doc = json.loads(payload)
    change(doc)
    text = canonical_json_bytes(doc).decode("utf-8")
    run_underneath(
        url,
        f"UPDATE {table} SET payload = %s, payload_sha256 = %s WHERE id = %s",
        params=(text, sha256_hex(text.encode("utf-8")), row_id),
    )


def _refused(url: str, args: list[str], *expected: str) -> None:
    """A read that cannot use a record that does not verify: exit 2, the record named, nothing served."""
    res = runner.invoke(app, ["--db", url, *args])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and res.stdout == ""
    for text in expected:
        assert text in res.stderr, res.stderr


def _failed_lint(url: str, args: list[str], *expected: str) -> None:
    """A lint's verdict on a record that does not verify: exit 1, the record named as a finding."""
    res = runner.invoke(app, ["--db", url, *args])
    assert res.exit_code == 1, res.output
    assert "Traceback" not in res.output and "content-hash" in res.stdout
    for text in expected:
        assert text in res.stdout, res.stdout


@pytest.fixture
def keyed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Signer:
    """A station key: every record written below is signed, and every read checks signatures."""
    path = tmp_path / "station.pem"
    signer = create_key(path)
    monkeypatch.setenv("CALIBCTL_SIGNING_KEY", str(path))
    return signer


# boards ----------


def _larger_square(doc: dict[str, Any]) -> None:
    doc["measurement"]["square_size_m"] *= 1.01


@pytest.fixture
def board_store(db_url: str) -> str:
    with Store.open(db_url) as store:
        store.add_board(measured_board())
    return db_url


def test_a_board_edited_with_its_payload_hash_recomputed_is_refused_by_every_read(board_store: str) -> None:
    _rewrite(board_store, "board_revisions", "name = 'A17'", _larger_square)
    why = "board A17@1 was changed after it was written (its chain hash no longer matches)"
    _refused(board_store, ["board", "show", "A17"], why, "calibctl db verify")
    _refused(board_store, ["board", "list"], why)
    with Store.open(board_store) as store:
        with pytest.raises(UnverifiedRecord, match=r"board A17@1 was changed"):
            store.get_board("A17")  # what capture, solve, lidar and hand-eye calibrate with
        with pytest.raises(UnverifiedRecord, match=r"board A17@1 was changed"):
            store.add_board(measured_board(square_mm=25.0))  # a new revision is checked against it
        assert store.board_revisions("A17") == [1]


def test_a_rechained_board_is_refused_with_keys(db_url: str, keyed: Signer) -> None:
    with Store.open(db_url, signer=keyed) as store:
        store.add_board(measured_board())
    _rewrite(db_url, "board_revisions", "name = 'A17'", _larger_square)
    rechain(db_url)
    for args in (["board", "show", "A17"], ["board", "list"]):
        _refused(db_url, args, "board A17@1 has a signature by key", "refusing to serve it")


# rig versions and their edges ----------


def _moved_edge(source: str) -> Callable[[Any], Any]:
    def move(cal: Any) -> Any:
        edges = []
        for edge in cal.edges:
            if edge.source == source:
                T = [list(r) for r in edge.T_parent_child]
                T[2][3] += 0.05  # 50 mm
                edge = edge.model_copy(update={"T_parent_child": tuple(map(tuple, T))})
            edges.append(edge)
        return cal.model_copy(update={"edges": edges})

    return move


@pytest.fixture
def rig_store(db_url: str) -> str:
    """STEREO-1@1 (two cameras), @2 = @1 plus a hand-eye edge, active."""
    with Store.open(db_url) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(serial="CAM-0001"), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(serial="CAM-0002"), activate=True, reason="solved", **WHO)
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, reason="rig solve", **WHO)
        store.add_rig_calibration(
            with_handeye_edge(rig_calibration()), activate=True, reason="hand-eye", **WHO
        )
    return db_url


@pytest.mark.parametrize("args", [["rig", "show", RIG], ["rig", "export", RIG, "--format", "json"]])
def test_a_rig_edge_moved_with_its_content_hash_recomputed_is_refused_without_keys(
    rig_store: str, args: list[str]
) -> None:
    _reseal_rig(rig_store, 2, _moved_edge("hand-eye"))
    _refused(
        rig_store, args, f"rig {RIG}@2 was changed after it was written (its chain hash no longer matches)"
    )


@pytest.mark.parametrize("args", [["rig", "lint", RIG], ["lint", "--rig", RIG]])
def test_rig_lint_fails_a_moved_rig_edge(rig_store: str, args: list[str]) -> None:
    _reseal_rig(rig_store, 2, _moved_edge("hand-eye"))
    _failed_lint(rig_store, args, f"rig {RIG}@2 was changed after it was written")


def test_a_moved_rig_edge_is_never_used_by_a_write(rig_store: str) -> None:
    _reseal_rig(rig_store, 2, _moved_edge("hand-eye"))
    with Store.open(rig_store) as store:
        with pytest.raises(UnverifiedRecord, match=rf"rig {RIG}@2 was changed"):
            store.get_rig_calibration(RIG)
        with pytest.raises(UnverifiedRecord, match=rf"rig {RIG}@2 was changed"):
            store.list_rig_calibrations(RIG)
        with pytest.raises(UnverifiedRecord, match=rf"rig {RIG}@2 was changed"):
            store.rollback_rig(RIG, 2, reason="restore the hand-eye edge", actor="qa", station="st1")
        store.rollback_rig(RIG, 1, reason="v2 refused", actor="qa", station="st1")
        assert store.active_rig_version(RIG) == 1


def test_a_lidar_edge_moved_with_its_content_hash_recomputed_is_refused_by_reads_and_writes(
    db_url: str,
) -> None:
    settings = load_settings(db=db_url, station="st1", operator="qa", env={})
    with Store.open(db_url) as store:
        store.add_rig(rig_definition().model_copy(update={"frames": ["lidar"]}))
        store.add_rig_calibration(rig_calibration(), activate=True, reason="rig solve", **WHO)
        store.add_artifact(calibration(serial="CAM-0001"), activate=True, reason="solved", **WHO)
    edge = _lidar(camera="CAM-0001@1").model_copy(update={"child_frame": "CAM-0001"})
    assert rig_lidar.store_lidar(settings, RIG, edge).calibration.version == 2
    _reseal_rig(db_url, 2, _moved_edge("lidar-board"))
    why = f"rig {RIG}@2 was changed after it was written (its chain hash no longer matches)"
    for args in (["rig", "show", RIG], ["rig", "export", RIG, "--format", "tf"]):
        _refused(db_url, args, why)
    _failed_lint(db_url, ["rig", "lint", RIG], why)
    with pytest.raises(UnverifiedRecord, match=rf"rig {RIG}@2 was changed"):
        rig_lidar.store_lidar(settings, RIG, edge)  # a new LiDAR result is never built on it
    assert _select(db_url, "SELECT count(*) FROM rig_calibrations") == [(2,)]


# the fleet log ----------


def _fleet(url: str, signer: Any = None) -> None:
    """amr-001 carries CAM-0001 (@1 assigned, @2 accepted); rollout r1 moves it to @2."""
    with Store.open(url, signer=signer) as store:
        store.add_artifact(calibration(), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(fx=801.0), activate=True, reason="solved", **WHO)
        store.add_fleet_event(fleet_event("register", serials=["CAM-0001"]))
        store.add_fleet_event(fleet_event("assign", serial="CAM-0001", version=1))
        rollout = FleetEvent(
            kind="rollout",
            rollout="r1",
            targets={"CAM-0001": 2},
            canary=["amr-001"],
            at=FIXED_TIME,
            reason="new lens",
            **WHO,
        )
        store.add_fleet_event(rollout)


def _target_back_to_1(doc: dict[str, Any]) -> None:
    doc["targets"] = {"CAM-0001": 1}


def test_a_fleet_event_edited_with_its_payload_hash_recomputed_is_refused(db_url: str) -> None:
    _fleet(db_url)
    _rewrite(db_url, "fleet_events", "kind = 'rollout'", _target_back_to_1)
    _refused(db_url, ["fleet", "status"], "fleet event 3 (r1, rollout) was changed after it was written")
    with Store.open(db_url) as store, pytest.raises(UnverifiedRecord, match=r"fleet event 3 \(r1, rollout\)"):
        store.fleet()


def test_a_promote_over_an_edited_fleet_log_refuses_and_writes_nothing(db_url: str) -> None:
    _fleet(db_url)
    _rewrite(db_url, "fleet_events", "kind = 'rollout'", _target_back_to_1)
    res = runner.invoke(app, ["--db", db_url, "fleet", "rollout", "promote", "r1", "--reason", "go"])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert "fleet event 3 (r1, rollout) was changed after it was written" in res.stderr
    assert _select(db_url, "SELECT count(*) FROM fleet_events") == [(3,)]


def test_a_rechained_fleet_log_is_refused_with_keys(db_url: str, keyed: Signer) -> None:
    _fleet(db_url, keyed)
    assert runner.invoke(app, ["--db", db_url, "fleet", "status"]).exit_code == 0
    _rewrite(db_url, "fleet_events", "kind = 'rollout'", _target_back_to_1)
    rechain(db_url)
    _refused(db_url, ["fleet", "status"], "fleet event 3 (r1, rollout) has a signature by key")


def test_a_deleted_newest_fleet_event_is_refused(db_url: str) -> None:
    _fleet(db_url)
    run_underneath(db_url, "DELETE FROM fleet_events WHERE kind = 'rollout'")
    _refused(db_url, ["fleet", "status"], "the fleet log ends at event 2 but its counter says 3")
