"""Output that never fails on encoding: '±' on a terminal or log that is not UTF-8 is written as '+/-'.

Under ``LC_ALL=C`` Python itself switches to UTF-8, but ``PYTHONIOENCODING=ascii`` (or latin-1, or a
CI runner's legacy code page) makes ``print('±')`` raise UnicodeEncodeError mid-report. Instead of
auditing every message for non-ASCII text, stdout and stderr get an error handler that spells the
few symbols calibctl prints in ASCII and replaces anything else with '?'.
"""

from __future__ import annotations

import codecs
import io
import sys

HANDLER = "calibctl-ascii"
_SPELLED = {
    "±": "+/-", "σ": "sigma", "°": " deg", "→": "->", "←": "<-", "—": "-", "–": "-", "…": "...",
    "×": "x", "µ": "u", "≤": "<=", "≥": ">=", "≈": "~", "✓": "ok", "✗": "x",
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
