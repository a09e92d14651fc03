"""calibctl.files: the one atomic writer and the one OSError translation."""

from __future__ import annotations

import errno
import os
import stat

import pytest

from calibctl.errors import AlreadyExistsError, FileSystemError
from calibctl.files import ENVIRONMENT_ERRNOS, file_errors, os_error, read_text, write_atomic


def test_write_atomic_writes_text_and_bytes_and_never_overwrites_without_force(tmp_path):
    path = tmp_path / "a.txt"
    write_atomic(path, "x ± 1\n")
    assert path.read_text(encoding="utf-8") == "x ± 1\n"
    with pytest.raises(AlreadyExistsError, match="already exists"):
        write_atomic(path, b"other")
    write_atomic(path, b"other", force=True)
    assert path.read_bytes() == b"other"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_new_files_follow_the_umask_and_overwrites_keep_their_mode(tmp_path):
    old = os.umask(0o077)
    try:
        private = write_atomic(tmp_path / "private", "x")
        assert stat.S_IMODE(private.stat().st_mode) == 0o600
        os.umask(0o002)
        shared = write_atomic(tmp_path / "shared", "x")
        assert stat.S_IMODE(shared.stat().st_mode) == 0o664
        shared.chmod(0o640)
        write_atomic(shared, "y", force=True)
        assert stat.S_IMODE(shared.stat().st_mode) == 0o640
    finally:
        os.umask(old)


def test_messages_name_the_path_and_the_reason(tmp_path):
    assert str(os_error(OSError(errno.ENOSPC, "x"), "write", tmp_path / "f")) == (
        f"cannot write {tmp_path / 'f'}: no space left on the device (free some space or write to another "
        "disk; "
        "no partial file was kept (images a capture had already stored are removed by `calibctl prune` an "
        "hour "
        "later))"
    )
    unlisted = os_error(OSError(errno.ENXIO, os.strerror(errno.ENXIO), "/dev/x"), "open")
    assert unlisted.message == f"cannot open /dev/x: {os.strerror(errno.ENXIO)}"
    with pytest.raises(FileSystemError, match=r"cannot write .*: it is a folder"):
        write_atomic(tmp_path, "x", force=True)
    with pytest.raises(FileSystemError, match="folder .* does not exist"):
        write_atomic(tmp_path / "no" / "f", "x")
    (tmp_path / "plain").write_text("x")
    with pytest.raises(
        FileSystemError, match=r"cannot write .*plain/f: .*plain is a file, not a folder"
    ) as file_parent:
        write_atomic(tmp_path / "plain" / "f", "x")
    assert file_parent.value.exit_code == 2 and "inside a folder" in (file_parent.value.hint or "")
    with (
        pytest.raises(FileSystemError, match="cannot list .*: permission denied"),
        file_errors("list", tmp_path),
    ):
        raise PermissionError(errno.EACCES, "Permission denied")
    assert errno.EROFS in ENVIRONMENT_ERRNOS and errno.EINVAL not in ENVIRONMENT_ERRNOS


def test_read_text_refuses_a_file_that_is_not_utf8(tmp_path):
    path = tmp_path / "latin1.yaml"
    path.write_bytes("sigma: ± 1\n".encode("latin-1"))
    with pytest.raises(FileSystemError, match=r"it is not UTF-8 text \(invalid start byte at byte 7\)"):
        read_text(path)
    with pytest.raises(FileSystemError, match="no such file or folder"):
        read_text(tmp_path / "missing.yaml")


def _special(kind: str, path, tmp_path) -> None:
    """Put a symlink, FIFO, folder or (where the kernel lets us, in tmp_path only) a device node at
    ``path``."""
    if kind == "symlink":
        victim = tmp_path / "victim.txt"
        victim.write_text("not ours\n")
        os.symlink(victim, path)
    elif kind == "dangling symlink":
        os.symlink(tmp_path / "nowhere", path)
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "folder":
        path.mkdir()
    elif kind == "device":
        try:
            os.mknod(path, 0o600 | stat.S_IFCHR, os.makedev(1, 3))  # a /dev/null twin, made in tmp_path only
        except (PermissionError, OSError) as exc:
            pytest.skip(f"cannot make a device node here ({exc})")


SPECIAL_KINDS = ["symlink", "dangling symlink", "fifo", "folder", "device"]


@pytest.mark.parametrize("kind", SPECIAL_KINDS)
def test_force_never_replaces_what_is_not_a_regular_file(tmp_path, kind):
    target = tmp_path / "out.json"
    _special(kind, target, tmp_path)
    before = os.lstat(target)
    with pytest.raises(FileSystemError, match="cannot write .*out.json: it is ") as refused:
        write_atomic(target, "x", force=True)
    assert refused.value.exit_code == 2
    after = os.lstat(target)
    assert (after.st_mode, after.st_ino) == (before.st_mode, before.st_ino)
    if kind == "symlink":
        assert (tmp_path / "victim.txt").read_text() == "not ours\n"
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_a_special_file_put_there_during_the_write_is_not_replaced(tmp_path, monkeypatch):
    target = tmp_path / "out.json"
    real = os.fdopen

    def fdopen(fd, *args, **kwargs):
        os.mkfifo(target)  # appears between the first look and the rename
        return real(fd, *args, **kwargs)

    monkeypatch.setattr("calibctl.files.os.fdopen", fdopen)
    with pytest.raises(FileSystemError, match="FIFO"):
        write_atomic(target, "x", force=True)
    assert stat.S_ISFIFO(os.lstat(target).st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_an_explicit_mode_is_used_for_a_new_and_a_replaced_file(tmp_path):
    key = write_atomic(tmp_path / "key.pem", b"k", mode=0o600)
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    key.chmod(0o644)
    write_atomic(key, b"k2", force=True, mode=0o600)
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
