"""Files calibctl writes, and the one translation of file-system failures into calibctl errors.

Every output file goes through ``write_atomic``: a temporary file in the target folder, then a rename,
so a reader never sees half a file and a failed write leaves the old file as it was. The new file
gets the mode the umask gives (0644 under the usual 022, so a robot's service user can read its
calibration); overwriting keeps the existing file's mode. Only regular files are ever replaced: a
symlink, FIFO, device node, socket or folder at the target is refused, ``--force`` or not (run as root,
``export -o /dev/sdX --force`` once replaced a disk's device node with a file).

``os_error`` turns an OSError (permission, read-only file system, disk full, is-a-directory, ...)
into one ``FileSystemError`` line naming the path and what to do; the CLI boundary applies the same
translation to any such error raised elsewhere, so no file-system problem ends in a traceback.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from calibctl.errors import AlreadyExistsError, FileSystemError, InputError

_FULL_HINT = (
    "free some space or write to another disk; no partial file was kept (images a capture had already "
    "stored are removed by `calibctl prune` an hour later)"
)
# errno -> (what happened, what to do). Anything not listed is reported with the system's own words.
_REASONS: dict[int, tuple[str, str]] = {
    errno.EACCES: ("permission denied", "check the permissions of that path, or choose another one"),
    errno.EPERM: ("operation not permitted", "check the permissions of that path, or choose another one"),
    errno.EROFS: ("read-only file system", "write to a writable folder instead"),
    errno.ENOSPC: ("no space left on the device", _FULL_HINT),
    errno.EDQUOT: ("disk quota exceeded", _FULL_HINT),
    errno.EISDIR: ("it is a folder", "name a file (for example FOLDER/camera.yaml)"),
    errno.ENOTDIR: ("a part of the path is not a folder", "check the path"),
    errno.ENOENT: ("no such file or folder", "check the path"),
    errno.ENAMETOOLONG: ("the name is too long", "choose a shorter path"),
    errno.EMFILE: ("too many open files", "raise the open-file limit (ulimit -n)"),
}
ENVIRONMENT_ERRNOS = frozenset(_REASONS) | {errno.EIO, errno.ELOOP, errno.EEXIST, errno.EBUSY, errno.ETXTBSY}
"""OSErrors that describe the machine, not a bug in calibctl: the CLI reports these in one line."""


def os_error(exc: OSError, action: str, path: Path | str | None = None) -> FileSystemError:
    """``cannot <action> <path>: <reason>`` with a hint, for any OSError."""
    where = path if path is not None else (exc.filename or "")
    reason, hint = _REASONS.get(exc.errno or -1, (exc.strerror or str(exc), "check the path and the disk"))
    target = f" {where}" if where != "" else ""
    return FileSystemError(f"cannot {action}{target}: {reason}", hint)


@contextmanager
def file_errors(action: str, path: Path | str | None = None) -> Iterator[None]:
    """Re-raise any OSError inside the block as a FileSystemError naming ``path``."""
    try:
        yield
    except OSError as exc:
        raise os_error(exc, action, path) from exc


def _umask() -> int:
    # The only portable way to read the umask is to set it and restore it at once; calibctl writes its
    # output files from the main thread only, so no other thread creates a file in between. (A capture's
    # image writer thread, workflows.camera.image_writes, may read it here too: meanwhile the main thread
    # computes the capture gates and creates no file.)
    current = os.umask(0o022)
    os.umask(current)
    return current


def new_file_mode(existing: Path | None = None) -> int:
    """The mode of an overwritten file is kept; a new file gets 0666 minus the umask."""
    if existing is not None:
        try:
            return existing.stat().st_mode & 0o7777
        except FileNotFoundError:
            pass
    return 0o666 & ~_umask()


def _kind(st_mode: int) -> str | None:
    """What a path is when it is not a regular file (None for a regular file)."""
    for test, name in (
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(st_mode):
            return name
    return None if stat.S_ISREG(st_mode) else "not a regular file"


def not_regular(path: Path | str) -> str | None:
    """What ``path`` is when it is not (a symbolic link to) a regular file, for a message: "a FIFO (named
    pipe)", "a folder", "a symbolic link loop or one to nothing"; None for a regular file."""
    try:
        st = os.stat(path)
    except OSError:
        return "a symbolic link loop or one to nothing" if os.path.islink(path) else "unreadable"
    return _kind(st.st_mode)


def existing_target(path: Path) -> os.stat_result | None:
    """``lstat`` of ``path`` (the link itself, never what it points to), or None when nothing is there.
    A path that exists and is not a regular file is refused: calibctl replaces only regular files, so
    ``--force`` never turns a symlink, a FIFO, a device node or a folder into a file of ours."""
    try:
        st = os.lstat(path)
    except (
        FileNotFoundError,
        NotADirectoryError,
    ):  # nothing there (a parent that is a file is named by the caller)
        return None
    except OSError as exc:
        raise os_error(exc, "write", path) from exc
    kind = _kind(st.st_mode)
    if kind is None:
        return st
    if kind == "a folder":
        raise os_error(IsADirectoryError(errno.EISDIR, "is a directory"), "write", path)
    raise FileSystemError(
        f"cannot write {path}: it is {kind}, not a regular file; calibctl replaces only regular "
        "files, --force included",
        "write to a regular file path (remove the special file yourself if it really is to be replaced)",
    )


def write_atomic(
    path: Path, data: str | bytes, *, force: bool = False, fsync: bool = False, mode: int | None = None
) -> Path:
    """Write ``data`` to ``path`` (temporary file + rename). Refuses to overwrite unless ``force``, and
    refuses, ``force`` or not, anything there that is not a regular file (symlink, FIFO, device, folder);
    an overwritten file keeps its mode. ``fsync`` makes the bytes durable before the rename
    (content-addressed stores need that); ``mode`` fixes the mode (a private key: 0600)."""
    path = Path(path)
    st = existing_target(path)
    if st is not None and not force:
        raise AlreadyExistsError(f"{path} already exists", "pass --force to overwrite it")
    if not path.parent.is_dir():
        if path.parent.exists():
            raise FileSystemError(
                f"cannot write {path}: {path.parent} is a file, not a folder",
                "choose an output path inside a folder",
            )
        raise FileSystemError(f"cannot write {path}: folder {path.parent} does not exist", "create it first")
    payload = data.encode("utf-8") if isinstance(data, str) else data
    if mode is None:
        mode = st.st_mode & 0o7777 if st is not None else new_file_mode()
    with file_errors("write", path):
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name[:24]}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as handle:
                handle.write(payload)
                handle.flush()
                if fsync:
                    os.fsync(handle.fileno())
                os.fchmod(handle.fileno(), mode)
            existing_target(path)  # a special file put there while we wrote is still refused, not replaced
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    return path


def open_regular(path: Path | str, what: str = "read") -> BinaryIO:
    """``path`` opened for reading in binary, refused (FileSystemError) unless it is a regular file or a
    folder (whose read error names it): opened non-blocking and checked with fstat, since a FIFO opened for
    reading waits for a writer forever (`import x.json` on a FIFO hung) and a device can stream without
    end."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    kind = _kind(os.fstat(fd).st_mode)
    if kind is not None and kind != "a folder":
        os.close(fd)
        raise FileSystemError(
            f"cannot {what} {path}: it is {kind}, not a regular file", "give the path of a regular file"
        )
    os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


def read_text(path: Path, what: str = "read", *, max_bytes: int | None = None) -> str:
    """A UTF-8 text file; a missing, unreadable or undecodable file, or one that is not a regular file, is a
    FileSystemError naming it. ``max_bytes``: never read more (a file that grew past it while read is refused,
    not cut off)."""
    with file_errors(what, path):
        try:
            if max_bytes is None:
                with open_regular(path, what) as handle:
                    return handle.read().decode("utf-8")
            chunks, total = [], 0
            with open_regular(
                path, what
            ) as handle:  # in chunks: read(max_bytes) would allocate all of it at once
                while total <= max_bytes and (chunk := handle.read(1 << 20)):
                    chunks.append(chunk)
                    total += len(chunk)
            data = b"".join(chunks)
            if total > max_bytes:
                raise InputError(
                    f"{path} is over the {max_bytes / 2**20:g} MiB input limit",
                    "raise CALIBCTL_MAX_INPUT_MB if such a file is real",
                )
            return data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FileSystemError(
                f"cannot {what} {path}: it is not UTF-8 text ({exc.reason} at byte {exc.start})",
                "is this the right file?",
            ) from exc
