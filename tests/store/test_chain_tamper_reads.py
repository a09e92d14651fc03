"""With keys configured, reads refuse what `db verify` would flag.

A careful forger (write access to the database, no signing key) changes a served record and recomputes its
content hash and every chain hash (``tamper.rechain``): the record's own hash and chain hash then match, so
only its signature or its chain link shows it. Each read command is run through the CLI on such a store:
exit 1, the record and `calibctl db verify` named, nothing printed as if valid. Without keys the same
forgery is served (what keys are for), and `db verify` with the keys (and a kept head) names every case.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.errors import UnverifiedRecord
from calibctl.signing import TrustedKeys, create_key
from calibctl.store import chain, served
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.store.tamper import rechain, run_underneath
from tests.store.test_chain_tamper import _reseal_artifact, _select
from tests.store.test_chain_tamper_rigs_checks import _reseal_rig

WHO = {"actor": "qa", "station": "st1"}
runner = CliRunner()


@pytest.fixture
def signed(db_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[str, TrustedKeys, str]:
    """A signed store: CAM-1 v1, v2 (v2 active), CAM-2 v1, rig STEREO-1 v1 active. The station reading it has
    only the public key (CALIBCTL_TRUSTED_KEYS). Returns (url, trusted keys, chain head kept elsewhere)."""
    signer = create_key(tmp_path / "station.pem")
    with Store.open(db_url, signer=signer) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(serial="CAM-1"), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(serial="CAM-1", fx=801.0), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(serial="CAM-2"), activate=True, reason="solved", **WHO)
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, reason="rig solve", **WHO)
        trusted = TrustedKeys({signer.key_id: signer.public})
        audit = store.verify(trusted, require_signature=True)
    assert audit.problems == []
    keys = tmp_path / "trusted"
    keys.mkdir()
    (keys / "station.pem").write_text(signer.public_pem())
    monkeypatch.setenv("CALIBCTL_TRUSTED_KEYS", str(keys))
    return db_url, trusted, audit.head()


def _fx_plus_5(url: str, serial: str = "CAM-1", version: int = 2) -> None:
    """fx + 5 px with content_sha256 and every chain hash recomputed: only the signature shows it."""
    (payload,) = _select(
        url, f"SELECT payload FROM calibration_artifacts WHERE serial = '{serial}' AND version = {version}"
    )[0]
    k = json.loads(payload)["camera_matrix"]
    k[0][0] += 5.0
    _reseal_artifact(url, serial, version, camera_matrix=k)
    rechain(url)


def _refused(args: list[str], url: str, record: str) -> None:
    res = runner.invoke(app, ["--db", url, *args])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and res.stdout == ""
    assert f"Error: {record} has a signature by key" in res.stderr and "refusing to serve it" in res.stderr
    assert "calibctl db verify" in res.stderr


READS = {
    "show": ["show", "CAM-1"],
    "show@N": ["show", "CAM-1@2"],
    "export json": ["export", "CAM-1", "--format", "json"],
    "export ros": ["export", "CAM-1", "--format", "ros"],
    "report": ["report", "CAM-1"],
}


@pytest.mark.parametrize("command", list(READS))
def test_a_read_command_refuses_a_rechained_forgery(signed, command: str, tmp_path: Path, monkeypatch):
    url, _, _ = signed
    monkeypatch.chdir(tmp_path)
    _fx_plus_5(url)
    _refused(READS[command], url, "CAM-1@2")
    assert not list(tmp_path.glob("*.html"))  # report wrote no page


def test_lint_serial_fails_a_rechained_forgery(signed):
    """lint gives the verdict on the record (exit 1, a content-hash error) where a read cannot run on it."""
    url, _, _ = signed
    _fx_plus_5(url)
    res = runner.invoke(app, ["--db", url, "lint", "--serial", "CAM-1", "--json"])
    assert res.exit_code == 1, res.output
    (result,) = json.loads(res.stdout)["results"]
    (finding,) = [f for f in result["findings"] if f["rule"] == "content-hash"]
    assert "CAM-1@2 has a signature by key" in finding["message"] and "db verify" in finding["fix"]


def test_export_to_a_file_writes_nothing(signed, tmp_path: Path):
    url, _, _ = signed
    _fx_plus_5(url)
    _refused(["export", "CAM-1", "--format", "opencv", "-o", str(tmp_path / "cam.yaml")], url, "CAM-1@2")
    assert not (tmp_path / "cam.yaml").exists()


def test_lint_all_names_the_forged_serial_and_lints_the_others(signed):
    url, _, _ = signed
    _fx_plus_5(url)
    res = runner.invoke(app, ["--db", url, "lint", "--all", "--json"])
    assert res.exit_code == 1, res.output
    report = json.loads(res.stdout)
    assert report["verdict"] == "fail"
    by_source = {r["source"]: r for r in report["results"]}
    forged = [f for f in by_source["CAM-1"]["findings"] if f["rule"] == "content-hash"]
    assert forged and "CAM-1@2 has a signature by key" in forged[0]["message"]
    assert not [f for f in by_source["CAM-2@1"]["findings"] if f["rule"] == "content-hash"]  # linted as usual


def test_rig_export_refuses_a_rechained_rig_forgery(signed):
    url, _, _ = signed
    _reseal_rig(
        url, 1, lambda cal: cal.model_copy(update={"fit_rms_px": {"CAM-0001": 0.01, "CAM-0002": 0.01}})
    )
    rechain(url)
    for fmt in ("json", "tf"):
        _refused(["rig", "export", RIG, "--format", fmt], url, f"rig {RIG}@1")


def test_without_keys_the_same_forgery_is_served(signed, monkeypatch):
    """What keys are for: a fully re-chained forgery is self-consistent; only a signature (or a kept head)
    shows it."""
    url, trusted, head = signed
    _fx_plus_5(url)
    monkeypatch.delenv("CALIBCTL_TRUSTED_KEYS")
    res = runner.invoke(app, ["--db", url, "show", "CAM-1", "--json"])
    assert res.exit_code == 0 and json.loads(res.stdout)["camera_matrix"][0][0] == 806.0
    with Store.open(url) as store:
        assert store.verify().problems == []
        assert store.verify(trusted).problems and store.verify(trusted, since=head).problems


# the matrix: each forgery that leaves the served record's own hashes intact --------------------------------


def _forged_rollback(url: str) -> None:
    """A rollback of CAM-1 to v1 appended with a correct chain link, unsigned (the forger has no key)."""
    run_underneath(
        url,
        "INSERT INTO activation_events (serial, version, previous_version, kind, actor, station, at, "
        "reason) VALUES ('CAM-1', 1, 2, 'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'routine')",
    )
    (count,) = _select(url, "SELECT count(*) FROM activation_events")[0]
    run_underneath(
        url,
        f"UPDATE activation_events SET chain_seq = {count} WHERE chain_seq IS NULL",
        f"UPDATE version_counters SET last_value = {count} WHERE scope = 'chain' AND key = 'event'",
    )
    rechain(url)


def _newest_event_deleted(url: str) -> None:
    """The event that activated CAM-2 removed (so CAM-2 has nothing active, CAM-1's last event is served)."""
    run_underneath(url, "DELETE FROM activation_events WHERE serial = 'CAM-2'")


def _signature_replayed(url: str) -> None:
    """v1's signature copied onto a v2 whose numbers were changed and re-chained."""
    _fx_plus_5(url)
    (sig, key) = _select(
        url, "SELECT signature, key_id FROM calibration_artifacts WHERE serial = 'CAM-1' AND version = 1"
    )[0]
    run_underneath(
        url,
        "UPDATE calibration_artifacts SET signature = %s, key_id = %s WHERE serial = 'CAM-1' AND version = 2",
        params=(sig, key),
    )


def _signature_stripped(url: str) -> None:
    _fx_plus_5(url)
    run_underneath(
        url,
        "UPDATE calibration_artifacts SET signature = NULL, key_id = NULL WHERE serial = 'CAM-1' AND "
        "version = 2",
    )


def _events_reordered(url: str) -> None:
    """CAM-1's two activation events swap ids: the older one (v1) becomes the latest, so v1 would be
    active."""
    ids = [r[0] for r in _select(url, "SELECT id FROM activation_events WHERE serial = 'CAM-1' ORDER BY id")]
    run_underneath(
        url,
        f"UPDATE activation_events SET id = 1000 WHERE id = {ids[0]}",
        f"UPDATE activation_events SET id = {ids[0]} WHERE id = {ids[1]}",
        f"UPDATE activation_events SET id = {ids[1]} WHERE id = 1000",
    )


MATRIX = {
    "fx + 5, re-sealed and re-chained": (_fx_plus_5, "CAM-1@2 has a signature by key"),
    "signature replayed from another record": (_signature_replayed, "CAM-1@2 has a signature by key"),
    "signature stripped after a re-chained edit": (
        _signature_stripped,
        "CAM-1@2 is not signed, but records before it in its chain are",
    ),
    "forged rollback, chained, unsigned": (
        _forged_rollback,
        "is not signed, but records before it in its chain are",
    ),
    "activation events reordered": (_events_reordered, "is out of order"),
}


@pytest.mark.parametrize("scenario", list(MATRIX))
def test_matrix_verify_names_it_and_no_read_serves_it(signed, scenario: str):
    url, trusted, head = signed
    forge, message = MATRIX[scenario]
    forge(url)
    with Store.open(url) as store:
        assert store.verify(trusted).problems or store.verify(trusted, since=head).problems
    with (
        Store.open(url, trusted=trusted) as store,
        pytest.raises(UnverifiedRecord, match="refusing to serve it") as exc,
    ):
        store.get_artifact("CAM-1")
    assert message in exc.value.message
    res = runner.invoke(
        app, ["--db", url, "show", "CAM-1"]
    )  # the sqlite3 read path on SQLite: the same refusal
    assert res.exit_code == 2 and message in res.stderr and res.stdout == ""


def test_a_deleted_newest_event_is_refused_where_it_was_served(signed):
    url, trusted, head = signed
    _newest_event_deleted(url)
    with Store.open(url) as store:
        assert any("counter" in p for p in store.verify(trusted).problems)
    res = runner.invoke(app, ["--db", url, "show", "CAM-1"])
    assert res.exit_code == 2, res.output
    assert "is the last record of its chain but the chain counter says chain_seq 3" in res.stderr


def test_an_untampered_signed_store_is_served_with_keys(signed):
    url, trusted, _ = signed
    with Store.open(url, trusted=trusted) as store:
        assert store.get_artifact("CAM-1").version == 2 and store.get_rig_calibration(RIG).version == 1
        found, _ = store.active_artifacts()
        assert sorted(found) == ["CAM-1", "CAM-2"] and not any(
            isinstance(v, UnverifiedRecord) for v in found.values()
        )
    res = runner.invoke(app, ["--db", url, "export", "CAM-1", "--format", "json"])
    assert res.exit_code == 0 and json.loads(res.stdout)["version"] == 2


def test_an_unsigned_store_with_keys_configured_is_still_served(db_url: str, tmp_path: Path):
    """Records written before a store had a key are unsigned and serve as before (db verify agrees)."""
    with Store.open(db_url) as store:
        store.add_artifact(calibration(serial="CAM-1"), activate=True, reason="solved", **WHO)
    signer = create_key(tmp_path / "k.pem")
    with Store.open(db_url, trusted=TrustedKeys({signer.key_id: signer.public})) as store:
        assert store.get_artifact("CAM-1").version == 1


def test_the_served_tables_are_the_chained_ones():
    assert {name: stream.table.name for name, stream in chain.STREAMS.items()} == served.TABLES


def test_a_signing_key_this_user_cannot_load_is_passed_over_when_a_trusted_folder_is_set(
    signed, tmp_path: Path, monkeypatch
):
    """Reads need only public keys: a station's private key kept for its service account does not stop
    `show`."""
    url, _, _ = signed
    _fx_plus_5(url)
    loose = tmp_path / "loose.pem"
    create_key(loose)
    loose.chmod(0o644)  # refused by load_signer (readable by others), as an unreadable file would be
    monkeypatch.setenv("CALIBCTL_SIGNING_KEY", str(loose))
    _refused(["show", "CAM-1"], url, "CAM-1@2")  # still checked against the trusted folder
    monkeypatch.delenv("CALIBCTL_TRUSTED_KEYS")
    res = runner.invoke(app, ["--db", url, "show", "CAM-1"])  # nothing else to check against: the key's error
    assert res.exit_code == 2 and "is readable by others" in res.stderr and res.stdout == ""


def test_an_empty_trusted_folder_checks_links_not_signatures(signed, tmp_path: Path, monkeypatch):
    url, _, _ = signed
    empty = tmp_path / "empty"
    empty.mkdir()
    monkeypatch.setenv("CALIBCTL_TRUSTED_KEYS", str(empty))
    assert (
        runner.invoke(app, ["--db", url, "show", "CAM-1"]).exit_code == 0
    )  # as db verify: nothing to check against
    _events_reordered(url)
    res = runner.invoke(app, ["--db", url, "show", "CAM-1"])
    assert res.exit_code == 2 and "is out of order" in res.stderr
