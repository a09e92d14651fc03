"""Durable capture: image files are on disk before the rows naming them commit, and a kill at any fsync,
link or statement leaves no row without its file and no temporary file."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import Engine, event, select

from calibctl.artifacts.common import sha256_hex
from calibctl.store.models import ImageRow
from calibctl.store.repository import Store
from tests.store import image_kill

REPO_ROOT = Path(__file__).resolve().parents[2]
MAX_POINTS = 60  # a guard against a sweep that never ends; the work has about 20 points


def _rows(store: Store) -> set[str]:
    return set(store._runner.run(lambda s: list(s.scalars(select(ImageRow.sha256)))))


def _check_no_row_without_its_file(store: Store) -> set[str]:
    rows = _rows(store)
    for sha in rows:
        path = store.image_dir / sha[:2] / sha
        assert path.exists(), f"image row {sha[:12]} has no file"
        assert sha256_hex(path.read_bytes()) == sha, f"image {sha[:12]} is not the bytes it names"
    strays = [p for p in store.image_dir.rglob("*") if p.is_file() and p.name.startswith(".")]
    assert strays == [], f"temporary files left behind: {strays}"
    return rows


def test_every_file_is_on_disk_when_its_row_commits(db_url: str):
    with Store.open(db_url) as store:
        data = image_kill.images("commit-check")
        seen: list[bool] = []

        def at_commit(conn: Any) -> None:
            seen.append(all((store.image_dir / sha_path(d)).exists() for d in data))

        event.listen(Engine, "commit", at_commit)
        try:
            store.put_images(data, retention_days=30)
        finally:
            event.remove(Engine, "commit", at_commit)
        assert seen and all(seen)
        assert _check_no_row_without_its_file(store) == {sha256_hex(d) for d in data}


def sha_path(data: bytes) -> str:
    sha = sha256_hex(data)
    return f"{sha[:2]}/{sha}"


def test_a_file_a_prune_removed_is_put_back_before_the_rows_commit(sqlite_url: str):
    with Store.open(sqlite_url) as store:
        (data,) = image_kill.images("prune")[:1]
        sha = store.put_image(data, retention_days=1)
        path = store.image_dir / sha_path(data)
        path.unlink()  # as a concurrent prune would, between our file write and our row lock
        assert store.put_image(data, retention_days=30) == sha
        assert path.read_bytes() == data


@pytest.mark.slow
def test_a_kill_at_any_point_of_a_capture_leaves_no_row_without_its_file(db_url: str):
    killed = 0
    for kill_at in range(1, MAX_POINTS + 1):
        tag = f"k{kill_at}"
        done = subprocess.run(
            [sys.executable, "-m", "tests.store.image_kill", db_url, str(kill_at), tag],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            check=False,
        )
        with Store.open(db_url) as store:
            rows = _check_no_row_without_its_file(store)
        shas = {sha256_hex(d) for d in image_kill.images(tag)}
        if done.returncode == 0:
            assert shas <= rows  # the run that got through stored everything
            break
        assert done.returncode == -signal.SIGKILL, done.stderr
        assert rows & shas in (set(), shas)  # one transaction: all rows of the batch or none
        killed += 1
    else:
        pytest.fail(f"the work did not finish within {MAX_POINTS} kill points")
    assert killed >= 10  # every fsync, link and statement of the batch was a kill point
