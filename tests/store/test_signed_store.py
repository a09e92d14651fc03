"""Signed records, key rotation, and chain heads: what stops a forger who re-computes the chains."""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.errors import UsageError
from calibctl.signing import TrustedKeys, create_key
from calibctl.store import audit
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.tamper import rechain, run_underneath

WHO = {"actor": "qa", "station": "st1"}


def _fill(url: str, key_path: Path) -> Store:
    signer = create_key(key_path)
    with Store.open(url, signer=signer) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(serial="CAM-1"), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(serial="CAM-1", fx=801.0), activate=True, reason="solved", **WHO)
        store.rollback("CAM-1", 1, reason="v2 drifts", **WHO)
    return store


def test_every_record_is_signed_and_verifies_against_the_trusted_key(db_url: str, tmp_path: Path):
    store = _fill(db_url, tmp_path / "k.pem")
    trusted = TrustedKeys({store.signer.key_id: store.signer.public})  # type: ignore[union-attr]
    with Store.open(db_url) as reader:
        report = reader.verify(trusted, require_signature=True)
        art = reader.get_artifact("CAM-1", 1)
    assert report.problems == [] and report.unsigned == 0
    assert report.signatures_checked == 1 + 2 + 3  # board, artifacts, events
    assert art.signature is not None and art.signature.key_id == store.signer.key_id  # type: ignore[union-attr]
    assert art.computed_sha256() == art.content_sha256  # the signature is not part of the content hash


def test_a_rechained_forgery_is_caught_by_the_signatures(db_url: str, tmp_path: Path):
    store = _fill(db_url, tmp_path / "k.pem")
    run_underneath(db_url, "UPDATE activation_events SET reason = 'routine' WHERE chain_seq = 3")
    rechain(db_url)
    trusted = TrustedKeys({store.signer.key_id: store.signer.public})  # type: ignore[union-attr]
    with Store.open(db_url) as reader:
        assert reader.verify().problems == []  # without keys the forged chain is self-consistent ...
        problems = reader.verify(trusted).problems  # ... with the key it is not
    assert problems == [
        "activation event 3 (CAM-1@1, rollback) has a signature by key "
        f"{store.signer.key_id[:16]} that does not match its content"
    ]  # type: ignore[union-attr]


def test_an_unsigned_record_after_signed_ones_is_a_finding(db_url: str, tmp_path: Path):
    _fill(db_url, tmp_path / "k.pem")
    with Store.open(
        db_url
    ) as unsigned_writer:  # a writer without the key (or a forger using calibctl's code)
        unsigned_writer.rollback("CAM-1", 2, reason="back again", **WHO)
        problems = unsigned_writer.verify().problems
    assert problems == [
        "activation event 4 (CAM-1@2, rollback) is not signed, but records before it in its chain are"
    ]


def test_rotation_keeps_old_signatures_verifiable(db_url: str, tmp_path: Path):
    old = _fill(db_url, tmp_path / "old.pem").signer
    new = create_key(tmp_path / "new.pem")
    with Store.open(db_url, signer=new) as store:
        store.add_artifact(calibration(serial="CAM-2"), activate=True, reason="solved", **WHO)
        both = TrustedKeys({old.key_id: old.public, new.key_id: new.public})  # type: ignore[union-attr]
        assert store.verify(both, require_signature=True).problems == []
        only_new = store.verify(TrustedKeys({new.key_id: new.public}), require_signature=True).problems
    assert len(only_new) == 6 and all(f"key {old.key_id[:16]}, which is not trusted" in p for p in only_new)  # type: ignore[union-attr]


def test_since_head_checks_only_what_came_after_and_catches_a_rewritten_past(db_url: str, tmp_path: Path):
    _fill(db_url, tmp_path / "k.pem")
    with Store.open(db_url) as store:
        head = store.verify().head()
        store.add_artifact(calibration(serial="CAM-2"), activate=True, reason="solved", **WHO)
        resumed = store.verify(since=head)
        # CAM-2@1 and its event; the event written without the key follows signed ones (before the head)
        assert resumed.records_checked == 2
        assert (
            resumed.problems
            == [
                "activation event 4 (CAM-2@1, activate) is not signed, but records before it in its chain are"
            ]
            == store.verify().problems
        )
        assert store.verify().head() == resumed.head()  # resuming ends at the same head as a full run
    run_underneath(
        db_url, "UPDATE calibration_artifacts SET operator = 'nobody' WHERE serial = 'CAM-1' AND version = 1"
    )
    rechain(db_url)
    with Store.open(db_url) as store:
        problems = store.verify(since=head).problems
    assert problems[0] == (
        "the history up to the given chain head was rewritten or truncated: its stream heads no "
        "longer hash to it"
    )


def test_since_head_catches_a_truncated_history(db_url: str, tmp_path: Path):
    _fill(db_url, tmp_path / "k.pem")
    with Store.open(db_url) as store:
        head = store.verify().head()
    run_underneath(  # remove CAM-1@2 and every trace of it: its events, the counters, the event chain
        db_url,
        "DELETE FROM activation_events WHERE chain_seq >= 2",
        "DELETE FROM calibration_artifacts WHERE serial = 'CAM-1' AND version = 2",
        "UPDATE version_counters SET last_value = 1",
    )
    with Store.open(db_url) as store:
        assert store.verify().problems == []  # a consistent, shorter history ...
        assert store.verify(since=head).problems != []  # ... that the kept head exposes


def test_a_malformed_head_is_a_usage_error():
    with pytest.raises(UsageError, match="is not a chain head"):
        audit.parse_head("calibctl-head-v1:1.2:abc")
