"""Capture sessions join the hash chains (migration 0009, one stream per serial), so edited corners with
their payload hash recomputed are named by `db verify` and, with keys, refused by reads."""

from __future__ import annotations

import json
import multiprocessing
from pathlib import Path

import pytest

from calibctl.artifacts.session import CaptureSession
from calibctl.errors import UnverifiedRecord
from calibctl.signing import TrustedKeys, create_key
from calibctl.store import audit as audit_module
from calibctl.store import codec, migrate
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.store import workers
from tests.store.documents import capture_session
from tests.store.tamper import rechain, run_underneath
from tests.store.test_chain_tamper import _select, problems_of


@pytest.fixture
def sessions(db_url: str) -> str:
    """CAM-0001: sessions a, b; CAM-0002: session c (unsigned store)."""
    with Store.open(db_url) as store:
        store.add_session(capture_session("aaaaaaaaaaa1", minutes_after=0))
        store.add_session(capture_session("aaaaaaaaaaa2", minutes_after=5))
        store.add_session(capture_session("ccccccccccc1", serial="CAM-0002", minutes_after=1))
        assert store.verify().problems == []
    return db_url


def _move_a_corner(url: str, session_id: str) -> None:
    """One corner moved by 0.5 px, the payload sha256 recomputed (the forgery no read saw before 0009)."""
    (payload,) = _select(url, f"SELECT payload FROM capture_sessions WHERE session_id = '{session_id}'")[0]
    data = json.loads(payload)
    data["views"][0]["corners_px"][0][0] += 0.5
    forged = codec.canonical_text(CaptureSession.model_validate(data))
    run_underneath(
        url,
        "UPDATE capture_sessions SET payload = %s, payload_sha256 = %s WHERE session_id = %s",
        params=(forged, codec.sha256_hex(forged.encode()), session_id),
    )


def test_sessions_are_chained_per_serial(sessions: str):
    assert _select(sessions, "SELECT session_id, id, chain_seq FROM capture_sessions ORDER BY id") == [
        ("aaaaaaaaaaa1", 1, 1),
        ("aaaaaaaaaaa2", 2, 2),
        ("ccccccccccc1", 3, 1),
    ]


def test_edited_corners_with_the_payload_hash_recomputed_are_named(sessions: str):
    _move_a_corner(sessions, "aaaaaaaaaaa1")
    assert problems_of(sessions) == [
        "capture session aaaaaaaaaaa1 was changed after it was written (its chain hash no longer matches)"
    ]


def test_a_deleted_session_breaks_its_serials_chain(sessions: str):
    run_underneath(sessions, "DELETE FROM capture_sessions WHERE session_id = 'aaaaaaaaaaa1'")
    assert problems_of(sessions) == [
        "capture session aaaaaaaaaaa2 is at chain position 2 but 1 was expected: records before it are "
        "missing"
    ]
    run_underneath(
        sessions, "DELETE FROM capture_sessions WHERE session_id = 'ccccccccccc1'"
    )  # a whole serial's
    assert (
        "the session counter of CAM-0002 is 1 but no record of it is stored: its records were deleted"
        in problems_of(sessions)
    )


def test_signed_sessions_a_rechained_edit_is_refused_by_verify_and_by_reads(db_url: str, tmp_path: Path):
    signer = create_key(tmp_path / "k.pem")
    with Store.open(db_url, signer=signer) as store:
        store.add_session(capture_session("aaaaaaaaaaa1"))
    trusted = TrustedKeys({signer.key_id: signer.public})
    with Store.open(db_url) as store:
        audit = store.verify(trusted, require_signature=True)
    assert audit.problems == [] and audit.signatures_checked == 1
    _move_a_corner(db_url, "aaaaaaaaaaa1")
    rechain(db_url)
    with Store.open(db_url) as store:
        assert store.verify().problems == []  # self-consistent without the key
        assert store.verify(trusted).problems == [
            f"capture session aaaaaaaaaaa1 has a signature by key {signer.key_id[:16]} that does not match "
            "its content"
        ]
        store.get_session("aaaaaaaaaaa1")  # without keys a read serves it ...
    with (
        Store.open(db_url, trusted=trusted) as store,
        pytest.raises(UnverifiedRecord, match="refusing to serve it"),
    ):
        store.get_session("aaaaaaaaaaa1")  # ... with keys it does not (report, solve's evidence)


def test_0009_chains_the_sessions_stored_before_it(sessions: str):
    engine = make_engine(sessions)
    try:
        assert migrate.downgrade(engine, "0008_chain_rig_definitions") == (
            "0016_chain_health_reports",
            "0008_chain_rig_definitions",
        )
        assert migrate.upgrade(engine) == ("0008_chain_rig_definitions", "0016_chain_health_reports")
    finally:
        engine.dispose()
    assert _select(sessions, "SELECT session_id, id, chain_seq FROM capture_sessions ORDER BY id") == [
        ("aaaaaaaaaaa1", 1, 1),
        ("ccccccccccc1", 2, 1),
        ("aaaaaaaaaaa2", 3, 2),
    ]  # numbered by started_at
    with Store.open(sessions) as store:
        audit = store.verify()
        assert audit.problems == [] and audit.records_checked == 3
        store.add_session(capture_session("aaaaaaaaaaa3", minutes_after=9))  # the backfilled counter goes on
        assert store.verify().problems == []
    # the id counter catches up with the ids the migration gave (it restarted at 1 after the downgrade)
    assert _select(
        sessions, "SELECT id, chain_seq FROM capture_sessions WHERE session_id = 'aaaaaaaaaaa3'"
    ) == [(4, 3)]
    _move_a_corner(sessions, "ccccccccccc1")
    assert problems_of(sessions) == [
        "capture session ccccccccccc1 was changed after it was written (its chain hash no longer matches)"
    ]


def test_a_head_printed_before_0009_checks_the_sessions_in_full(sessions: str):
    with Store.open(sessions) as store:
        full = store.verify()
    old = [name for name in full.last_ids if name != "session"]  # the seven streams a head named before 0009
    ids = ".".join(str(full.last_ids[name]) for name in old)
    head = f"{audit_module.HEAD_PREFIX}:{ids}:{audit_module._digest({n: full.heads[n] for n in old})}"
    with Store.open(sessions) as store:
        resumed = store.verify(since=head)
    assert resumed.problems == [] and resumed.records_checked == 3
    with Store.open(sessions) as store:
        head = store.verify().head()
        store.add_session(capture_session("aaaaaaaaaaa3", minutes_after=9))
        assert store.verify(since=head).records_checked == 1  # only the new one


def test_concurrent_capture_stations_chain_every_session(db_url: str):
    """Four processes store sessions of two serials at once: every one is numbered, chained and verifies (a
    clash on the next id between serials' writers is retried, not lost)."""
    ctx = multiprocessing.get_context("spawn")
    barrier, results = ctx.Barrier(4), ctx.Queue()
    procs = [
        ctx.Process(target=workers.write_sessions, args=(db_url, 6, w, barrier, results)) for w in range(4)
    ]
    for p in procs:
        p.start()
    reports = [results.get(timeout=300) for _ in procs]  # a hang guard for a broken child, not a speed check
    for p in procs:
        p.join()
    assert [err for _, _, err in reports if err] == []
    ids = _select(db_url, "SELECT id FROM capture_sessions ORDER BY id")
    assert [r[0] for r in ids] == list(range(1, 25))
    assert sorted(_select(db_url, "SELECT serial, max(chain_seq) FROM capture_sessions GROUP BY serial")) == [
        ("CAM-0", 12),
        ("CAM-1", 12),
    ]
    assert problems_of(db_url) == []
