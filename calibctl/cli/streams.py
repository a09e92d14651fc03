"""Output that never fails on encoding: '±' on a terminal or log that is not UTF-8 is written as '+/-'.

Under ``LC_ALL=C`` Python itself switches to UTF-8, but ``PYTHONIOENCODING=ascii`` (or latin-1, or a
CI runner's legacy code page) makes ``print('±')`` raise UnicodeEncodeError mid-report. Instead of
auditing every message for non-ASCII text, stdout and stderr get an error handler that spells the
few symbols calibctl prints in ASCII and replaces anything else with '?'.
"""

from __future__ import annotations

import codecs
import io
import os
import sys

HANDLER = "calibctl-ascii"
_SPELLED = {
    "±": "+/-",
    "σ": "sigma",
    "°": " deg",
    "→": "->",
    "←": "<-",
    "—": "-",
    "–": "-",
    "…": "...",
    "×": "x",
    "µ": "u",
    "≤": "<=",
    "≥": ">=",
    "≈": "~",
    "✓": "ok",
    "✗": "x",
}


def _spell(err: UnicodeError) -> tuple[str, int]:
    if not isinstance(err, UnicodeEncodeError):
        raise err
    chunk = err.object[err.start : err.end]
    return "".join(_SPELLED.get(ch, "?") for ch in chunk), err.end


codecs.register_error(HANDLER, _spell)


def make_output_safe() -> None:
    """Give stdout/stderr the spelling error handler when they are strict text streams."""
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper) and stream.errors == "strict":
            stream.reconfigure(errors=HANDLER)


EXIT_CLOSED_PIPE = 141
"""Exit code when the reader of stdout went away (``calibctl export X | head -1``): 128 + SIGPIPE, what
a shell reports for any tool stopped by a closed pipe; never 1 (a verdict) and never a traceback."""


def silence_closed_stdout() -> int:
    """Point stdout at /dev/null after its reader closed the pipe, so the rest of the output (and the
    flush at exit) goes nowhere instead of raising BrokenPipeError again; returns the exit code to use.
    Python's recommended pattern (docs.python.org/3/library/signal.html#note-on-sigpipe)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no real file descriptor behind stdout (a test runner's buffer)
        pass
    finally:
        os.close(devnull)
    return EXIT_CLOSED_PIPE


def flush_stdout_at_exit() -> None:
    """Flush stdout before the interpreter does, so a reader that closed the pipe after the last write
    ends calibctl with EXIT_CLOSED_PIPE and no 'Exception ignored ... BrokenPipeError' message."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        raise SystemExit(silence_closed_stdout()) from None
