"""The content-addressed image directory beside the database.

Images are what a re-capture would need and what an auditor may want to look at, but they are big
(~350x the corners they produce), so they are kept for a retention period only. Each file is named
by its sha256 (``<dir>/ab/ab12...``); its row in ``images`` says when it expires. Where the directory is:

* ``CALIBCTL_IMAGE_DIR`` when set;
* SQLite: ``calibctl-images/`` next to the database file;
* PostgreSQL (or in-memory SQLite): ``./calibctl-images`` (set CALIBCTL_IMAGE_DIR on every station
  to a shared mount when the store is shared).
"""

from __future__ import annotations

import datetime as dt
import errno
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from sqlalchemy import delete, select
from sqlalchemy.engine import URL
from sqlalchemy.orm import Session

from calibctl.artifacts.common import sha256_hex, utc_now
from calibctl.errors import UsageError
from calibctl.files import file_errors, write_atomic
from calibctl.store.engine import sqlite_path
from calibctl.store.models import ImageRow
from calibctl.store.runner import Runner

IMAGE_DIR_ENV = "CALIBCTL_IMAGE_DIR"
IMAGE_DIR_NAME = "calibctl-images"
_HEX = set("0123456789abcdef")


def default_image_dir(url: URL, env: Mapping[str, str] | None = None) -> Path:
    env = os.environ if env is None else env
    if env.get(IMAGE_DIR_ENV):
        return Path(env[IMAGE_DIR_ENV])
    db_file = sqlite_path(url)
    if db_file is not None:
        return db_file.resolve().parent / IMAGE_DIR_NAME
    return Path(IMAGE_DIR_NAME)


ORPHAN_GRACE_S = 3600.0  # a capture writes its files moments before their rows commit; an hour is ample


def image_file(image_dir: Path, sha256: str) -> Path:
    if len(sha256) != 64 or not set(sha256) <= _HEX:
        raise UsageError(f"'{sha256}' is not a sha256 (64 lower-case hex digits)")
    return image_dir / sha256[:2] / sha256


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _link_fd(fd: int, path: Path, folder: int, size: int) -> None:
    try:
        os.link(f"/proc/self/fd/{fd}", path.name, dst_dir_fd=folder)
    except FileExistsError:
        if path.stat().st_size == size:  # written by another capture meanwhile: same name, same content
            return
        path.unlink()  # a damaged file under a content address: replace it
        os.link(f"/proc/self/fd/{fd}", path.name, dst_dir_fd=folder)


def _link_anonymous(path: Path, data: bytes) -> bool:
    """Write ``data`` to an unnamed file in ``path``'s folder (O_TMPFILE), fsync it, then give it its name.

    A kill at any point before the link leaves nothing behind (the kernel frees an unnamed file), so no
    temporary file can be left over. False when the file system has no O_TMPFILE (the caller falls back).
    """
    flag = getattr(os, "O_TMPFILE", 0)
    if not flag:
        return False
    try:
        fd = os.open(path.parent, flag | os.O_WRONLY, 0o644)
    except OSError as exc:
        if exc.errno in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL, errno.ENOENT):
            return False
        raise
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
        try:
            # A dir fd makes CPython call linkat(..., AT_SYMLINK_FOLLOW): it links the file the /proc
            # entry names, where plain link() would try to link the /proc symlink itself (EXDEV).
            folder = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
            try:
                _link_fd(fd, path, folder, len(data))
            finally:
                os.close(folder)
        except FileNotFoundError:  # no /proc: use the named-temporary-file path
            return False
    finally:
        os.close(fd)
    return True


def write_durably(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that, once this returns, the file and its name survive a crash.

    The file's bytes are fsynced before it gets its name (a crash can never leave the name pointing at a
    short file), and the folder is fsynced after (so the name itself is durable). This runs *before* the
    image rows commit: a row in ``images`` always has its file. The file fsync measured 0.7-1 ms per
    1280x960 PNG on the bench machine (benchmarks/bench_e2e.py).
    """
    with file_errors("write the image", path):
        created = not path.parent.is_dir()
        path.parent.mkdir(parents=True, exist_ok=True)
        if created:
            _fsync_dir(path.parent.parent)
        if not _link_anonymous(path, data):
            write_atomic(path, data, force=True, fsync=True)
        _fsync_dir(path.parent)


def _has_file(path: Path, size: int) -> bool:
    return path.exists() and path.stat().st_size == size


class ImageStore:
    """The Store's images: files in ``image_dir``, their rows in the database."""

    def __init__(self, runner: Runner, image_dir: Path) -> None:
        self._runner = runner
        self.image_dir = image_dir

    def put_image(self, data: bytes, *, retention_days: int) -> str:
        """Keep ``data`` for ``retention_days`` (an image stored again keeps the later expiry); returns its
        sha256."""
        return self.put_images([data], retention_days=retention_days)[0]

    def put_images(self, images: Sequence[bytes], *, retention_days: int) -> list[str]:
        """``put_image`` for several images with one transaction for all their rows; their sha256s, in order.

        One commit instead of one per image: each SQLite commit fsyncs the WAL, and 20 separate ones took
        ~40 ms of the ~55 ms a 20-image folder spent here (benchmarks/bench_e2e.py, 1280x960 PNGs).
        """
        if retention_days < 0:
            raise UsageError(f"image retention must be 0 days or more, got {retention_days}")
        shas = [sha256_hex(data) for data in images]
        by_sha = dict(zip(shas, images, strict=True))
        now = utc_now()
        expires = now + dt.timedelta(days=retention_days)

        def missing() -> list[str]:
            return [
                sha
                for sha in sorted(by_sha)
                if not _has_file(image_file(self.image_dir, sha), len(by_sha[sha]))
            ]

        def work(s: Session) -> None:
            for sha in sorted(by_sha):  # one lock order for every writer (PostgreSQL FOR UPDATE)
                row = s.get(ImageRow, sha, with_for_update=True)
                if row is None:
                    s.add(
                        ImageRow(sha256=sha, size_bytes=len(by_sha[sha]), stored_at=now, expires_at=expires)
                    )
                elif row.expires_at < expires:
                    row.expires_at = expires
            # A prune that committed between the writes below and these locks may have deleted a file we
            # wrote; holding the rows now, put any such file back before the rows commit.
            for sha in missing():
                write_durably(image_file(self.image_dir, sha), by_sha[sha])

        # Files first (durable), rows after: a kill at any point leaves no row without its file. A file
        # whose rows never committed is an unreferenced, complete file that the next capture reuses.
        for sha in missing():
            write_durably(image_file(self.image_dir, sha), by_sha[sha])
        self._runner.run(work, write=True, retry_conflicts=True)
        return shas

    def image_path(self, sha256: str) -> Path | None:
        """The file of a kept image, or None when it was never stored, has been pruned or is missing."""
        path = image_file(self.image_dir, sha256)
        row = self._runner.run(lambda s: s.get(ImageRow, sha256))
        return path if row is not None and path.exists() else None

    def orphan_images(self, now: dt.datetime | None = None, grace_s: float = ORPHAN_GRACE_S) -> list[Path]:
        """Image files with no row, last written more than ``grace_s`` before ``now``: what a capture that
        failed after writing its images (disk full, a kill) left behind. The grace keeps a capture in
        progress (files first, rows a moment later) out of it."""
        if not self.image_dir.is_dir():
            return []
        cutoff = (now or utc_now()).timestamp() - grace_s
        on_disk = {
            p.name: p
            for p in self.image_dir.glob("[0-9a-f][0-9a-f]/*")
            if len(p.name) == 64 and set(p.name) <= _HEX and p.is_file() and p.stat().st_mtime < cutoff
        }
        if not on_disk:
            return []
        names = sorted(on_disk)

        def work(s: Session) -> set[str]:
            found: set[str] = set()
            for start in range(0, len(names), 500):  # bounded IN lists (SQLite caps bound parameters)
                found.update(
                    s.scalars(select(ImageRow.sha256).where(ImageRow.sha256.in_(names[start : start + 500])))
                )
            return found

        known = self._runner.run(work)
        return [path for sha, path in sorted(on_disk.items()) if sha not in known]

    def prune_images(self, now: dt.datetime | None = None) -> int:
        """Delete image files (and their rows) whose retention has expired; returns how many.
        Never touches corners, sessions or artifacts."""
        when = now or utc_now()

        def work(s: Session) -> int:
            expired = list(
                s.scalars(select(ImageRow.sha256).where(ImageRow.expires_at <= when).with_for_update())
            )
            if expired:
                s.execute(delete(ImageRow).where(ImageRow.sha256.in_(expired)))
                for sha in expired:
                    image_file(self.image_dir, sha).unlink(missing_ok=True)
            return len(expired)

        pruned = int(self._runner.run(work, write=True))
        for path in self.orphan_images(when):  # a failed capture's files: no row refers to them
            path.unlink(missing_ok=True)
            pruned += 1
        return pruned
