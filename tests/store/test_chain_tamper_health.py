"""Health reports are sealed at ingest (revision 0016: hash-chained in one stream, signed with the station's
key): the health gate a promote decides with reads only reports as they were ingested. A failing report edited
to pass (its payload hash recomputed, with or without its chain hash), or deleted, is refused by name; `db
verify` names it too."""

from __future__ import annotations

import json
from datetime import timedelta
from pathlib import Path

import pytest

from calibctl.artifacts.common import canonical_json_bytes, sha256_hex, utc_now
from calibctl.errors import UnverifiedRecord
from calibctl.signing import Signer, TrustedKeys, create_key
from calibctl.store import migrate
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.cli.fleet.fleet_store import run, small_fleet
from tests.store.documents import fleet_event, health_report
from tests.store.tamper import rechain, run_underneath
from tests.store.test_chain_tamper import _select

ROBOTS = ["amr-001"]
SINCE = utc_now() - timedelta(days=400)


def _ingested(url: str, signer: Signer | None = None) -> None:
    """amr-001 carries CAM-0001; it reported a pass (r-1) and a fail (r-2)."""
    with Store.open(url, signer=signer) as store:
        store.add_fleet_event(fleet_event("register", serials=["CAM-0001"]))
        failing = {"kind": "check", "rms_px": 2.5, "verdict": "fail"}
        assert (
            store.add_health_reports(
                [health_report("CAM-0001"), health_report("CAM-0001", source_id="r-2", **failing)]
            )
            == []
        )


def _passes(url: str) -> None:
    """r-2 edited to pass, its payload hash and column copies recomputed (as someone with write access
    would)."""
    (payload,) = _select(url, "SELECT payload FROM health_reports WHERE source_id = 'r-2'")[0]
    doc = json.loads(payload)
    doc.update(rms_px=0.2, verdict="pass")
    text = canonical_json_bytes(doc).decode("utf-8")
    run_underneath(
        url,
        "UPDATE health_reports SET payload = %s, payload_sha256 = %s, rms_px = 0.2, verdict = 'pass' "
        "WHERE source_id = 'r-2'",
        params=(text, sha256_hex(text.encode("utf-8"))),
    )


def _gate(url: str, trusted: TrustedKeys | None = None) -> list[tuple[str, str | None]]:
    with Store.open(url, trusted=trusted) as store:
        return [(r.source_id, r.verdict) for r in store.gate_reports(ROBOTS, ["CAM-0001"], SINCE)]


def test_reports_are_chained_at_ingest_and_the_gate_reads_them(db_url: str) -> None:
    _ingested(db_url)
    rows = _select(db_url, "SELECT source_id, chain_seq, chain_prev IS NULL FROM health_reports ORDER BY id")
    assert rows == [("r-1", 1, True), ("r-2", 2, False)]
    assert _gate(db_url) == [("r-1", "pass"), ("r-2", "fail")]
    with Store.open(db_url) as store:
        assert store.verify().problems == []


def test_a_report_edited_to_pass_is_refused_by_the_gate_and_named_by_verify(db_url: str) -> None:
    _ingested(db_url)
    _passes(db_url)
    with pytest.raises(
        UnverifiedRecord, match=r"health report r-2 \(amr-001, CAM-0001 check\) was changed after"
    ):
        _gate(db_url)
    with Store.open(db_url) as store:
        assert any("health report r-2" in p for p in store.verify().problems)


def test_a_rechained_report_is_refused_with_keys(db_url: str, tmp_path: Path) -> None:
    signer = create_key(tmp_path / "station.pem")
    _ingested(db_url, signer)
    _passes(db_url)
    rechain(db_url)
    trusted = TrustedKeys({signer.key_id: signer.public})
    with pytest.raises(
        UnverifiedRecord, match=r"health report r-2 .* has a signature by key .* does not match"
    ):
        _gate(db_url, trusted)
    assert _gate(db_url) == [
        ("r-1", "pass"),
        ("r-2", "pass"),
    ]  # without keys a re-chained stream is consistent


def test_a_deleted_report_is_refused_by_the_gate(db_url: str) -> None:
    _ingested(db_url)
    run_underneath(db_url, "DELETE FROM health_reports WHERE source_id = 'r-2'")
    with pytest.raises(UnverifiedRecord, match="numbered 1 to 2 but 1 are stored: a report was deleted"):
        _gate(db_url)
    with Store.open(db_url) as store:  # a passing one ingested after it does not hide it
        assert store.add_health_reports([health_report("CAM-0001", source_id="r-3")]) == []
    run_underneath(db_url, "DELETE FROM health_reports WHERE source_id = 'r-1'")
    with pytest.raises(UnverifiedRecord, match="numbered 1 to 3 but 1 are stored"):
        _gate(db_url)


def test_a_promote_over_an_edited_report_refuses_and_promotes_nothing(
    sqlite_url: str, tmp_path: Path
) -> None:
    small_fleet(sqlite_url, {"amr-1": "CAM-1", "amr-2": "CAM-2"})
    args = ["rollout", "start", "r1", "--target", "CAM-1@2", "--target", "CAM-2@2", "--canary", "amr-1"]
    assert run(sqlite_url, "fleet", *args, "--reason", "new lens").exit_code == 0
    doc = {"source_id": "a1/c", "robot": "amr-1", "serial": "CAM-1", "kind": "check", "rms_px": 2.5}
    (tmp_path / "r.jsonl").write_text(
        json.dumps({**doc, "verdict": "fail", "time": utc_now().isoformat()}) + "\n"
    )
    assert run(sqlite_url, "fleet", "ingest", str(tmp_path / "r.jsonl")).exit_code == 0
    held = run(sqlite_url, "fleet", "rollout", "promote", "r1", "--reason", "go")
    assert held.exit_code == 1 and "is held" in held.stderr
    (payload,) = _select(sqlite_url, "SELECT payload FROM health_reports WHERE source_id = 'a1/c'")[0]
    edited = canonical_json_bytes({**json.loads(payload), "rms_px": 0.2, "verdict": "pass"}).decode("utf-8")
    run_underneath(
        sqlite_url,
        "UPDATE health_reports SET payload = %s, payload_sha256 = %s, rms_px = 0.2, verdict = 'pass'",
        params=(edited, sha256_hex(edited.encode("utf-8"))),
    )
    (events,) = _select(sqlite_url, "SELECT count(*) FROM fleet_events")[0]
    refused = run(sqlite_url, "fleet", "rollout", "promote", "r1", "--reason", "go")
    assert refused.exit_code == 2, refused.output  # could not run: a record it needs does not verify
    assert "health report a1/c (amr-1, CAM-1 check) was changed after it was written" in refused.stderr
    assert "Traceback" not in refused.output
    assert _select(sqlite_url, "SELECT count(*) FROM fleet_events")[0] == (events,)  # nothing promoted
    status = run(sqlite_url, "fleet", "status")  # the rollout's gate is not shown as if it held
    assert status.exit_code == 2 and "health report a1/c" in status.stderr


def test_reports_stored_before_0016_are_chained_by_the_migration(db_url: str) -> None:
    _ingested(db_url)
    engine = make_engine(db_url)
    try:
        migrate.downgrade(engine, "0015_checkpoints_fleet_ckpt")
        migrate.upgrade(engine)
    finally:
        engine.dispose()
    rows = _select(db_url, "SELECT source_id, chain_seq, signature FROM health_reports ORDER BY id")
    assert rows == [("r-1", 1, None), ("r-2", 2, None)]
    assert _gate(db_url) == [("r-1", "pass"), ("r-2", "fail")]
    with Store.open(db_url) as store:
        assert store.verify().problems == []
        assert store.add_health_reports([health_report("CAM-0001", source_id="r-3")]) == []
    assert _select(db_url, "SELECT chain_seq FROM health_reports WHERE source_id = 'r-3'") == [(3,)]


def _trends_refused(url: str, *expected: str) -> None:
    res = run(url, "fleet", "trends", "CAM-0001")
    assert res.exit_code == 2, res.output  # could not run: a report it reads does not verify
    assert res.stdout == "" and "Traceback" not in res.output and "calibctl db verify" in res.stderr
    for text in expected:
        assert text in res.stderr, res.stderr


def test_fleet_trends_refuses_an_edited_or_deleted_report(db_url: str) -> None:
    _ingested(db_url)
    assert run(db_url, "fleet", "trends", "CAM-0001").exit_code == 0
    _passes(db_url)
    _trends_refused(
        db_url,
        "health report r-2 (amr-001, CAM-0001 check) was changed after it was written",
        "fleet trends refuses to read it",
    )
    run_underneath(db_url, "DELETE FROM health_reports WHERE source_id = 'r-2'")
    _trends_refused(db_url, "numbered 1 to 2 but 1 are stored: a report was deleted")


def test_fleet_trends_refuses_a_rechained_report_with_keys(
    db_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "station.pem"
    signer = create_key(path)
    _ingested(db_url, signer)
    _passes(db_url)
    rechain(db_url)
    assert run(db_url, "fleet", "trends", "CAM-0001").exit_code == 0  # consistent without keys
    monkeypatch.setenv("CALIBCTL_SIGNING_KEY", str(path))
    _trends_refused(db_url, "health report r-2 (amr-001, CAM-0001 check) has a signature by key")
