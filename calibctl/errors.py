"""The one error hierarchy of calibctl.

Every failure a user can cause is a ``CalibctlError``. Each class knows its exit code (the contract
factory scripts and CI rely on) and carries a hint that names the fix. The CLI boundary
(``calibctl.cli.main``) is the only place that turns these into ``Error: ...`` lines and exit codes;
anything else that escapes is a bug and keeps its traceback.

Exit codes:
    0  success; the check passed
    1  the tool worked and the verdict is "fail" (gate, lint, verify, tampered import)
    2  the tool could not do its job (usage, unreadable input, unknown serial/board/version, database, a
       stored record it needs that does not verify)

``named_list`` is the one "a, b, c and 4 more" of the messages that name a few of many things (files,
lines, versions, labels); it lives here because every layer, core included, already imports this module.
"""

from __future__ import annotations

from collections.abc import Sequence

EXIT_OK = 0
EXIT_VERDICT_FAIL = 1
EXIT_CANNOT_RUN = 2


class CalibctlError(Exception):
    """Base class. ``message`` says what went wrong, ``hint`` says what to do about it."""

    exit_code: int = EXIT_CANNOT_RUN

    def __init__(self, message: str, hint: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint

    def __str__(self) -> str:
        return self.message if not self.hint else f"{self.message} ({self.hint})"


class UsageError(CalibctlError):
    """The command line or a setting asks for something that cannot be done."""


class InputError(CalibctlError):
    """An input file or stream is unreadable, malformed or not what it claims to be."""


class FileSystemError(CalibctlError):
    """A file or folder cannot be read or written: permission, read-only, disk full, is-a-directory."""


class WorkerDiedError(CalibctlError):
    """A worker process died under the work (killed, out of memory, a crash in a native library)."""


class NotFoundError(CalibctlError):
    """An unknown serial, board, revision, version or session."""


class AlreadyExistsError(CalibctlError):
    """A thing that must be unique exists already (board name, output file without --force)."""


class DatabaseError(CalibctlError):
    """The store is unreachable, locked for too long, or refused the operation."""


class DatabaseUnreachableError(DatabaseError):
    """The store cannot be reached at all (no server, network cut, file's folder missing): nothing was written
    by the failed call. The station spools its units when it sees this (``workflows.station.spool``)."""


class StaleActiveVersionError(DatabaseError):
    """A compare-and-set write (rollback) saw an active version that another writer has since changed."""


class DatabaseOutOfDateError(DatabaseError):
    """The database schema is older than this calibctl; ``calibctl db upgrade`` migrates it."""


class NumericalError(CalibctlError):
    """A numerical step could not produce a trustworthy answer (diverged, non-finite, too few data)."""


class VerdictFailed(CalibctlError):
    """The tool ran and the verdict is "fail": gates, lint, verify. Exit 1."""

    exit_code = EXIT_VERDICT_FAIL


class InconsistentDataError(VerdictFailed):
    """The tool measured the input and found it contradicts itself (a rig's frames that no rigid,
    synchronised set of cameras could have taken): a verdict on the data, exit 1, not a failure to run."""


class IntegrityError(VerdictFailed):
    """Content does not match its recorded sha256: the bytes were changed after they were written."""


class UnverifiedRecord(CalibctlError):
    """A stored record a read serves or a write builds on does not verify (its hash, chain link or signature
    shows it was changed, deleted or forged after it was written): the command cannot run, exit 2. The message
    names the record; the commands whose job is the integrity verdict (``db verify``, ``lint``, ``rig lint``)
    report the same finding as a verdict, exit 1."""


EXTRA_PACKAGES = {
    "postgres": "psycopg[binary]>=3.1.4",
    "plots": "matplotlib>=3.8",
    "bags": "rosbags>=0.11.9",
}
"""Each extra's requirement, as pyproject.toml's optional-dependencies say (a test keeps them equal)."""


class MissingExtraError(CalibctlError):
    """An optional part of calibctl is not installed: ``calibctl[postgres]`` or ``calibctl[plots]``.

    The hint installs the extra's package into the environment calibctl runs in. It never names
    ``calibctl[extra]`` for an index: calibctl is installed from its wheel and no index holds that name
    (whoever published it would have their code installed)."""

    def __init__(self, extra: str, purpose: str, module: str | None) -> None:
        from calibctl import __version__

        spec = EXTRA_PACKAGES.get(extra, extra)
        wheel = f"calibctl-{__version__}-py3-none-any.whl"
        super().__init__(
            f"{purpose} needs the Python package {(module or extra).split('.')[0]}, which is not installed",
            f"install it into calibctl's environment: pipx inject calibctl '{spec}' (pipx); "
            f"uv tool install --with '{spec}' ./{wheel} (uv, from the wheel calibctl was installed from); "
            f"python -m pip install '{spec}' (a virtualenv)",
        )


def named_list(items: Sequence[object], limit: int, sep: str = ", ") -> str:
    """The first ``limit`` of ``items`` and how many more: ``a, b, c and 4 more`` (all of them when they fit).
    Only the items shown are turned into text."""
    shown = sep.join(str(item) for item in items[:limit])
    return shown + (f" and {len(items) - limit} more" if len(items) > limit else "")
