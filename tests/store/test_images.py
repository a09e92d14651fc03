"""The content-addressed image store beside the database, with retention."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from pathlib import Path

import pytest

from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.errors import UsageError
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.store.documents import capture_session

PNG_A = b"\x89PNG\r\n\x1a\n image A"
PNG_B = b"\x89PNG\r\n\x1a\n image B, a little longer"


@pytest.fixture
def store(db_url: str) -> Iterator[Store]:
    with Store.open(db_url) as opened:
        yield opened


def test_images_are_stored_under_their_sha256(store: Store):
    sha = store.put_image(PNG_A, retention_days=30)
    assert sha == sha256_hex(PNG_A)
    path = store.image_path(sha)
    assert path is not None and path.name == sha and path.read_bytes() == PNG_A
    assert path.parent.parent == store.image_dir
    assert store.image_path(sha256_hex(b"never stored")) is None
    with pytest.raises(UsageError, match="is not a sha256"):
        store.image_path("../../etc/passwd")


def test_prune_deletes_expired_images_only(store: Store):
    store.add_session(capture_session())
    store.add_artifact(calibration(), activate=True, actor="qa", station="st1", reason="solved")
    short = store.put_image(PNG_A, retention_days=1)
    long = store.put_image(PNG_B, retention_days=30)
    short_path = store.image_path(short)
    assert store.prune_images(utc_now()) == 0  # nothing has expired yet
    assert store.prune_images(utc_now() + dt.timedelta(days=2)) == 1
    assert store.image_path(short) is None and short_path is not None and not short_path.exists()
    assert store.image_path(long) is not None
    counts = store.counts()
    assert (counts["images"], counts["sessions"], counts["artifacts"], counts["events"]) == (1, 1, 1, 1)
    assert store.prune_images(utc_now() + dt.timedelta(days=31)) == 1
    assert store.counts()["images"] == 0 and store.get_session("0123456789ab").serial == "CAM-0001"


def test_storing_an_image_again_keeps_the_later_expiry(store: Store):
    sha = store.put_image(PNG_A, retention_days=1)
    assert store.put_image(PNG_A, retention_days=10) == sha
    assert store.put_image(PNG_A, retention_days=2) == sha  # a shorter retention does not shorten it
    assert store.prune_images(utc_now() + dt.timedelta(days=5)) == 0
    assert store.prune_images(utc_now() + dt.timedelta(days=11)) == 1


def test_negative_retention_is_refused(store: Store):
    with pytest.raises(UsageError, match="image retention must be 0 days or more, got -1"):
        store.put_image(PNG_A, retention_days=-1)


def test_sqlite_images_live_next_to_the_database(sqlite_url: str, tmp_path: Path, monkeypatch):
    with Store.open(sqlite_url) as store:
        assert store.image_dir == tmp_path.resolve() / "calibctl-images"
    monkeypatch.setenv("CALIBCTL_IMAGE_DIR", str(tmp_path / "shared"))
    with Store.open(sqlite_url) as store:
        assert store.image_dir == tmp_path / "shared"


def test_several_images_are_stored_in_one_call_in_order(store: Store):
    shas = store.put_images([PNG_B, PNG_A, PNG_B], retention_days=5)
    assert shas == [sha256_hex(PNG_B), sha256_hex(PNG_A), sha256_hex(PNG_B)]
    for sha, data in ((shas[0], PNG_B), (shas[1], PNG_A)):
        path = store.image_path(sha)
        assert path is not None and path.read_bytes() == data
    assert store.counts()["images"] == 2
    assert store.put_images([PNG_A], retention_days=10) == [shas[1]]  # the later expiry wins, as put_image
    assert store.prune_images(utc_now() + dt.timedelta(days=6)) == 1
    assert store.image_path(shas[0]) is None and store.image_path(shas[1]) is not None
    with pytest.raises(UsageError, match="image retention must be 0 days or more, got -2"):
        store.put_images([PNG_A], retention_days=-2)


def test_a_failed_captures_files_are_found_and_pruned_after_the_grace(store: Store, monkeypatch):
    """Disk full (or a kill) between the files and their rows left files neither prune nor verify saw."""
    from calibctl.errors import DatabaseError
    from calibctl.store.images import ORPHAN_GRACE_S, image_file

    kept = store.put_image(PNG_A, retention_days=30)
    real_run = store._runner.run

    def full_disk(work, *, write=False, retry_conflicts=False):
        if write:
            raise DatabaseError("the disk of the store is full; nothing was written")
        return real_run(work, write=write, retry_conflicts=retry_conflicts)

    monkeypatch.setattr(store._runner, "run", full_disk)
    with pytest.raises(DatabaseError):
        store.put_images([PNG_B], retention_days=30)
    monkeypatch.setattr(store._runner, "run", real_run)
    orphan = image_file(store.image_dir, sha256_hex(PNG_B))
    assert orphan.exists() and store.image_path(sha256_hex(PNG_B)) is None
    assert store.orphan_images() == []  # within the grace: a capture may be about to commit its rows
    later = utc_now() + dt.timedelta(seconds=ORPHAN_GRACE_S + 60)
    assert store.orphan_images(later) == [orphan]
    assert store.prune_images(later) == 1
    assert not orphan.exists() and store.image_path(kept) is not None  # a kept image is never touched
