"""The spool file (store.spool): a spool the previous calibctl wrote (format 1) opens, upgraded, its records
intact; a record set aside is kept and never pending again; with a key every record is signed, and a record
rewritten with its sha256, renumbered, stripped of its signature or signed by another key is refused."""

from __future__ import annotations

import hashlib
import json
import sqlite3
from pathlib import Path

import pytest

from calibctl.errors import AlreadyExistsError, IntegrityError, NotFoundError, UsageError
from calibctl.signing import Signer, TrustedKeys, create_key
from calibctl.store.codec import canonical_text
from calibctl.store.spool import Spool
from tests.artifacts.factories import calibration
from tests.store.documents import capture_session

STORE = "sqlite:////factory/central/calibctl.db"
# the spool schema of calibctl before format 2 (set-aside and signed records), as it wrote it
FORMAT_1_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE boards (
    ref TEXT PRIMARY KEY, name TEXT NOT NULL, revision INTEGER NOT NULL, document TEXT NOT NULL
);
CREATE TABLE units (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, serial TEXT NOT NULL, session_id TEXT NOT NULL UNIQUE,
    queued_at TEXT NOT NULL, session TEXT NOT NULL, artifact TEXT, session_stored INTEGER NOT NULL,
    images TEXT NOT NULL, record_sha256 TEXT NOT NULL, synced_at TEXT, version INTEGER);
"""


def opened(
    path: Path, signer: Signer | None = None, trusted: TrustedKeys | None = None, station: str = "line-3"
) -> Spool:
    return Spool.open(path, station=station, store=STORE, signer=signer, trusted=trusted)


def keyed(path: Path, signer: Signer) -> Spool:
    return opened(path, signer, TrustedKeys.load(None, signer))


def queue(spool: Spool, *session_ids: str) -> list[int]:
    """Queue a calibration (its session already in the store: no images) per session id, serial CAM-0001."""
    art = calibration("CAM-0001")
    return [spool.queue(capture_session(sid), art, session_stored=True) for sid in session_ids]


def problems(spool: Spool) -> dict[int, str | None]:
    return {r.seq: spool.problem(r) for r in spool.records(pending_only=True)}


def write_format_1(path: Path) -> str:
    """A format-1 spool holding one record whose sha256 is computed here as the previous calibctl did."""
    session, art = capture_session("0123456789ab"), calibration("CAM-0001")
    session_text, art_text = canonical_text(session), canonical_text(art)
    parts = ["calibctl-spool-1", "line-3", STORE, "CAM-0001", "0123456789ab", session_text, art_text, "1", ""]
    sha = hashlib.sha256("\n".join(parts).encode("utf-8")).hexdigest()
    with sqlite3.connect(path) as conn:
        conn.executescript(FORMAT_1_SCHEMA)
        conn.executemany(
            "INSERT INTO meta VALUES (?, ?)",
            [
                ("format", "calibctl-spool-1"),
                ("station", "line-3"),
                ("store", STORE),
                ("created_at", "2026-11-26T08:00:00+00:00"),
            ],
        )
        conn.execute(
            "INSERT INTO units (serial, session_id, queued_at, session, artifact, session_stored, images, "
            "record_sha256) VALUES ('CAM-0001', '0123456789ab', '2026-11-26T08:01:00+00:00', ?, ?, 1, "
            "'[]', ?)",
            (session_text, art_text, sha),
        )
    conn.close()
    return sha


def meta_and_columns(path: Path) -> tuple[dict[str, str], list[str]]:
    with sqlite3.connect(path) as conn:
        meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
        columns = [row[1] for row in conn.execute("PRAGMA table_info(units)")]
    conn.close()
    return meta, columns


def test_a_format_1_spool_opens_upgraded_with_its_record_intact_and_can_be_set_aside(tmp_path: Path) -> None:
    path = tmp_path / "spool.sqlite"
    sha = write_format_1(path)
    with pytest.raises(UsageError, match="belongs to station 'line-3', not 'line-4'"):
        opened(path, station="line-4")
    meta, columns = meta_and_columns(path)
    assert meta["format"] == "calibctl-spool-1" and columns[-1] == "version"  # refused: left as it was
    with opened(path) as spool:
        [record] = spool.records(pending_only=True)
        assert record.record_sha256 == sha and spool.problem(record) is None
        session, art = spool.opened(record)
        assert session.session_id == "0123456789ab" and art is not None and art.serial == "CAM-0001"
        assert spool.counts() == (1, 0, 0)
        aside = spool.set_aside(record.seq, reason="unit scrapped", operator="op-ana")
        assert (aside.set_aside_reason, aside.set_aside_by, aside.key_id) == ("unit scrapped", "op-ana", None)
    meta, columns = meta_and_columns(path)
    assert meta["format"] == "calibctl-spool-2"
    assert columns[-5:] == ["set_aside_at", "set_aside_reason", "set_aside_by", "key_id", "signature"]
    with opened(path) as again:  # opened again: upgraded once, the set-aside kept
        assert again.counts() == (0, 0, 1) and [r.seq for r in again.records(set_aside_only=True)] == [1]


def test_a_record_set_aside_is_kept_and_unknown_synced_or_set_aside_records_are_refused(
    tmp_path: Path,
) -> None:
    with opened(tmp_path / "spool.sqlite") as spool:
        queue(spool, "aaaaaaaaaaa1", "aaaaaaaaaaa2", "aaaaaaaaaaa3")
        spool.mark_synced(1, 2)
        before = spool.records()
        with pytest.raises(NotFoundError, match=r"there is no spool record 9 in .*spool.sqlite"):
            spool.set_aside(9, reason="r", operator="op")
        with pytest.raises(
            UsageError,
            match=r"spool record 1 \(CAM-0001, session aaaaaaaaaaa1\) was synced .* as v2; "
            "a stored record is not set aside",
        ):
            spool.set_aside(1, reason="r", operator="op")
        assert spool.records() == before
        aside = spool.set_aside(2, reason="lens cracked", operator="op-ana")
        assert aside.set_aside_at is not None and aside.synced_at is None
        with pytest.raises(
            AlreadyExistsError,
            match=r"spool record 2 \(CAM-0001, session aaaaaaaaaaa2\) was set "
            r"aside .* by op-ana: lens cracked; nothing changed",
        ):
            spool.set_aside(2, reason="again", operator="op-bo")
        assert [r.seq for r in spool.records(pending_only=True)] == [3]
        assert [(r.seq, r.set_aside_reason) for r in spool.records(set_aside_only=True)] == [
            (2, "lens cracked")
        ]
        assert [r.seq for r in spool.records()] == [1, 2, 3]  # kept: nothing is deleted
        assert spool.counts() == (1, 1, 1)


def test_keyed_records_are_signed_and_a_rewrite_a_renumbering_or_a_removed_signature_is_refused(
    tmp_path: Path,
) -> None:
    signer = create_key(tmp_path / "station.key")
    path = tmp_path / "spool.sqlite"
    with keyed(path, signer) as spool:
        queue(spool, "bbbbbbbbbbb1", "bbbbbbbbbbb2", "bbbbbbbbbbb3", "bbbbbbbbbbb4")
        assert {r.key_id for r in spool.records()} == {signer.key_id} and all(
            r.signature for r in spool.records()
        )
        assert problems(spool) == {1: None, 2: None, 3: None, 4: None}
        record = spool.records()[0]
        doc = json.loads(record.artifact_text or "")
        doc["rms_px"] = 0.01  # a better number, and the sha256 recomputed as calibctl computes it
        text = json.dumps(doc)
        rehashed = spool._record_sha256(
            record.serial,
            record.session_id,
            record.session_text,
            text,
            record.session_stored,
            record.image_shas,
        )
    with sqlite3.connect(path) as conn:
        conn.execute("UPDATE units SET artifact = ?, record_sha256 = ? WHERE seq = 1", (text, rehashed))
        conn.execute(
            "UPDATE units SET seq = 99 WHERE seq = 2"
        )  # records 2 and 3 swapped: the sync order changed
        conn.execute("UPDATE units SET seq = 2 WHERE seq = 3")
        conn.execute("UPDATE units SET seq = 3 WHERE seq = 99")
        conn.execute("UPDATE units SET key_id = NULL, signature = NULL WHERE seq = 4")
    conn.close()
    with opened(path) as unkeyed:  # the sha256 alone cannot see any of it
        assert problems(unkeyed) == {1: None, 2: None, 3: None, 4: None}
    with keyed(path, signer) as spool:
        found = problems(spool)
        mismatch = (
            f"has a signature by key {signer.key_id[:16]} that does not match its content: it was rewritten"
        )
        assert all((found[seq] or "").startswith(mismatch) for seq in (1, 2, 3))
        assert (found[4] or "").startswith("is not signed, and this station signs its spool")
        with pytest.raises(IntegrityError) as refused:
            spool.opened(spool.records()[0])
    assert refused.value.exit_code == 1
    assert refused.value.message.startswith(
        "spool record 1 (CAM-0001, session bbbbbbbbbbb1) has a signature by key"
    )
    assert "calibctl station set-aside 1 --reason TEXT" in (refused.value.hint or "")


def test_another_key_an_unkeyed_spool_read_with_a_key_and_a_keyed_one_read_without(tmp_path: Path) -> None:
    station_key, other_key = create_key(tmp_path / "station.key"), create_key(tmp_path / "other.key")
    path = tmp_path / "spool.sqlite"
    with opened(path) as unkeyed:
        queue(unkeyed, "ccccccccccc1")
    with keyed(path, other_key) as by_other:
        queue(by_other, "ccccccccccc2")
    with keyed(path, station_key) as spool:
        queue(spool, "ccccccccccc3")
        found = problems(spool)
    assert (found[1] or "").startswith("is not signed")  # queued before the station had its key: refused
    assert found[2] == (
        f"is signed by key {other_key.key_id[:16]}, which is not trusted: neither this station's key "
        "nor one in its trusted_keys folder"
    )
    assert found[3] is None
    (tmp_path / "trusted").mkdir()
    (tmp_path / "trusted" / "other.pem").write_text(other_key.public_pem())  # a rotated key, kept trusted
    with opened(path, station_key, TrustedKeys.load(tmp_path / "trusted", station_key)) as rotated:
        assert problems(rotated)[2] is None
    with opened(path) as without_key:  # a station without a key checks the sha256 alone (unkeyed)
        assert problems(without_key) == {1: None, 2: None, 3: None}


@pytest.mark.parametrize("with_key", [False, True])
def test_a_deleted_record_is_missing_keyed_or_not_and_stops_the_sync_before_the_next(
    tmp_path: Path, with_key: bool
) -> None:
    path = tmp_path / "spool.sqlite"
    signer = create_key(tmp_path / "station.pem") if with_key else None
    spool = keyed(path, signer) if signer else opened(path)
    assert queue(spool, "aaaaaaaaaaa1", "aaaaaaaaaaa2", "aaaaaaaaaaa3") == [1, 2, 3]
    spool.close()
    with sqlite3.connect(path) as conn:
        conn.execute("DELETE FROM units WHERE seq = 2")
    spool = keyed(path, signer) if signer else opened(path)
    assert spool.missing() == [2]
    first, third = spool.records(pending_only=True)
    assert spool.gap_before(first) is None  # the record before the gap still syncs
    refused = spool.gap_before(third)
    assert refused is not None and refused.exit_code == 1
    assert refused.message.startswith(f"spool record 2 is missing from {path}")
    assert "record 3 (CAM-0001) and the records after it were not synced" in refused.message
    assert "calibctl station set-aside 2 --reason TEXT" in (refused.hint or "")
    spool.close()
