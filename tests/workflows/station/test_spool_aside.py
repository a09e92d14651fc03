"""A spool record the sync refuses no longer blocks the queue: set aside (kept, never synced), the records
behind it are stored in order, none twice; with the station's key a record rewritten with its sha256 is
refused, naming it."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from calibctl.errors import (
    AlreadyExistsError,
    DatabaseError,
    InputError,
    IntegrityError,
    NotFoundError,
    UsageError,
)
from calibctl.signing import TrustedKeys, create_key
from calibctl.store.repository import Store
from calibctl.store.spool import image_file
from calibctl.workflows.station.station import PASS, QUEUED, SYNCED
from calibctl.workflows.station.sync import open_spool, set_aside, status, sync
from tests.workflows.station.spool_setup import queue_three, run


def rewrite_rms(spool: Path, seq: int, *, rehash: bool) -> None:
    """Type a better RMS into record ``seq``'s calibration; ``rehash``: and recompute its sha256 as calibctl
    does
    (what anyone who can write the file can do)."""
    from calibctl.store.spool import Spool

    with sqlite3.connect(spool) as conn:
        row = conn.execute(
            "SELECT serial, session_id, session, artifact, session_stored, images FROM units WHERE seq = ?",
            (seq,),
        ).fetchone()
        doc = json.loads(row[3])
        doc["rms_px"] = 0.01
        text = json.dumps(doc)
        conn.execute("UPDATE units SET artifact = ? WHERE seq = ?", (text, seq))
        if rehash:
            station, store = (
                conn.execute("SELECT value FROM meta WHERE key = ?", (k,)).fetchone()[0]
                for k in ("station", "store")
            )
            sha = Spool(spool, conn, station, store)._record_sha256(
                row[0], row[1], row[2], text, bool(row[4]), json.loads(row[5])
            )
            conn.execute("UPDATE units SET record_sha256 = ? WHERE seq = ?", (sha, seq))
    conn.close()


def test_a_changed_record_set_aside_lets_the_queue_behind_it_sync_in_order_and_is_kept(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)  # records 1 CAM-1, 2 CAM-2, 3 CAM-1 (CAM-1 v1 stored online)
    rewrite_rms(spool, 1, rehash=False)
    blocked = run(settings, shots, ["CAM-3"], spool)  # the store is up: the station's sync stops at record 1
    assert [(r.serial, r.status, r.spool_record) for r in blocked] == [("CAM-3", QUEUED, 4)]
    assert (
        "spool record 1 (CAM-1, session " in blocked[0].message
        and "does not match its sha256" in blocked[0].message
    )
    assert "calibctl station set-aside 1 --reason TEXT" in (blocked[0].hint or "")
    with open_spool(settings, spool) as opened:
        refused = sync(settings, opened)
        assert refused.synced == [] and isinstance(refused.error, IntegrityError) and refused.left == 4
        assert "spool record 1 (CAM-1" in refused.error.message
        assert "calibctl station set-aside 1 --reason TEXT" in (refused.error.hint or "")
        tampered, third = opened.records()[0], opened.records()[2]
        with (
            open_spool(settings, spool) as other,
            other.sync_lock(),  # a sync running elsewhere
            pytest.raises(DatabaseError, match=r"is syncing the spool .*; this one set nothing aside"),
        ):
            set_aside(settings, opened, 1, "rms typed in by hand")
        with pytest.raises(UsageError, match="needs a reason"):
            set_aside(settings, opened, 1, "  ")
        with pytest.raises(InputError, match="the reason holds a NUL character"):
            set_aside(settings, opened, 1, "x\x00y")
        assert opened.records()[0] == tampered  # nothing changed by the refusals
        done = set_aside(settings, opened, 1, "rms typed in by hand (ticket QA-7)")
    assert (done.unit.seq, done.unit.serial, done.unit.operator, done.unit.reason, done.queued) == (
        1,
        "CAM-1",
        "op-ana",
        "rms typed in by hand (ticket QA-7)",
        3,
    )
    lines = run(settings, shots, ["CAM-2"], spool)  # the station's own sync before the next unit goes on
    assert [(r.serial, r.status, r.version, r.spool_record) for r in lines] == [
        ("CAM-2", SYNCED, 1, 2),
        ("CAM-1", SYNCED, 2, 3),
        ("CAM-3", SYNCED, 1, 4),
        ("CAM-2", PASS, 2, None),
    ]
    with Store.open(settings.db_url) as store:
        cam1 = store.list_artifacts("CAM-1")
        assert [a.version for a in cam1] == [1, 2]  # the set-aside unit is not a version: none skipped
        assert cam1[1].provenance.session_id == third.session_id
        sessions = {s.session_id for s in store.list_sessions()}
        assert tampered.session_id not in sessions and len(sessions) == 5  # two online, three synced
        assert store.verify().problems == []
    with open_spool(settings, spool) as opened:
        again = sync(settings, opened)
        assert again.synced == [] and again.error is None and again.left == 0
        found = status(opened)
        assert found.queued == [] and found.synced == 3
        assert [(a.seq, a.serial, a.operator, a.images) for a in found.set_aside] == [
            (1, "CAM-1", "op-ana", 12)
        ]
        kept = opened.records()[0]
        assert kept.session_text == tampered.session_text and kept.artifact_text == tampered.artifact_text
        assert all(
            image_file(opened.image_dir, sha).exists() for sha in kept.image_shas
        )  # kept after the prune
        with pytest.raises(
            AlreadyExistsError, match=r"spool record 1 \(CAM-1, .*\) was set aside .* by op-ana"
        ):
            set_aside(settings, opened, 1, "again")
        with pytest.raises(UsageError, match=r"spool record 2 \(CAM-2, .*\) was synced .* as v1"):
            set_aside(settings, opened, 2, "too late")
        with pytest.raises(NotFoundError, match="there is no spool record 5"):
            set_aside(settings, opened, 5, "no such record")


def test_with_the_stations_key_a_record_rewritten_with_its_sha256_is_refused_naming_it(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    signer = create_key(tmp_path / "station.key")
    keyed = settings.model_copy(update={"signing_key": str(signer.path)})
    spool = tmp_path / "spool.sqlite"
    queue_three(keyed, shots, spool, central)
    rewrite_rms(spool, 2, rehash=True)
    with open_spool(settings, spool) as unkeyed:  # without the key the rewrite is not seen
        assert [q.intact for q in status(unkeyed).queued] == [True, True, True]
    with open_spool(keyed, spool) as opened:
        assert [q.intact for q in status(opened).queued] == [True, False, True]
        refused = sync(keyed, opened)
        assert [u.seq for u in refused.synced] == [1] and refused.left == 2
        assert isinstance(refused.error, IntegrityError)
        assert refused.error.message.startswith(
            f"spool record 2 (CAM-2, session {opened.records()[1].session_id}) "
            f"has a signature by key {signer.key_id[:16]} that does not match"
        )
        set_aside(keyed, opened, 2, "rewritten: rms 0.01")
        done = sync(keyed, opened)
    assert [(u.seq, u.serial, u.version) for u in done.synced] == [(3, "CAM-1", 3)] and done.left == 0
    with Store.open(settings.db_url) as store:
        assert store.serials() == ["CAM-1"]  # CAM-2's only unit was set aside
        assert all(
            a.signature is not None and a.signature.key_id == signer.key_id
            for a in store.list_artifacts("CAM-1")[1:]
        )
        assert store.verify(TrustedKeys.load(None, signer)).problems == []


FORMAT_1_COLUMNS = (
    "seq, serial, session_id, queued_at, session, artifact, session_stored, images, record_sha256, "
    "synced_at, version"
)


def test_a_spool_queued_by_the_previous_calibctl_is_upgraded_and_synced_in_order(
    settings, shots: Path, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    queue_three(settings, shots, spool, central)
    with sqlite3.connect(spool) as conn:  # the file as the format-1 code wrote it: its table, its format
        conn.executescript(f"""
            CREATE TABLE units_1 (
                seq INTEGER PRIMARY KEY AUTOINCREMENT, serial TEXT NOT NULL, session_id TEXT NOT NULL UNIQUE,
                queued_at TEXT NOT NULL, session TEXT NOT NULL, artifact TEXT,
                session_stored INTEGER NOT NULL,
                images TEXT NOT NULL, record_sha256 TEXT NOT NULL, synced_at TEXT, version INTEGER);
            INSERT INTO units_1 SELECT {FORMAT_1_COLUMNS} FROM units;
            DROP TABLE units;
            ALTER TABLE units_1 RENAME TO units;
            UPDATE meta SET value = 'calibctl-spool-1' WHERE key = 'format';""")
    conn.close()
    with open_spool(settings, spool) as opened:
        assert [q.intact for q in status(opened).queued] == [True, True, True]
        done = sync(settings, opened)
    assert [(u.seq, u.serial, u.version) for u in done.synced] == [
        (1, "CAM-1", 2),
        (2, "CAM-2", 1),
        (3, "CAM-1", 3),
    ]
    assert done.error is None and done.left == 0
    with sqlite3.connect(spool) as conn:
        assert conn.execute("SELECT value FROM meta WHERE key = 'format'").fetchone()[0] == "calibctl-spool-2"
    conn.close()
