"""Output that needs no rich: JSON, stored text made safe to print, and lint's finding lines.

``calibctl lint FILE`` and ``export`` print through here, so they start without importing rich (about
20 ms of a 0.3 s start, benchmarks/results/startup.md); ``cli.render`` re-exports these for every other
command.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from calibctl.artifacts.lint import Finding

SEVERITY_COLOURS = {"error": "red", "warning": "yellow"}  # anything else: cyan
_ANSI = {"red": "31", "green": "32", "yellow": "33", "cyan": "36"}


def _default(obj: Any) -> Any:
    if hasattr(obj, "model_dump"):
        return obj.model_dump(mode="json")
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if hasattr(obj, "isoformat"):
        return obj.isoformat()
    raise TypeError(f"cannot serialise {type(obj).__name__} to JSON")


def emit_json(obj: Any) -> None:
    """Print one JSON document to stdout (machine output: no colour, no wrapping)."""
    if hasattr(obj, "model_dump"):
        obj = obj.model_dump(mode="json")
    text = json.dumps(obj, indent=2, sort_keys=False, default=_default, allow_nan=False)
    print(text)


# C0 and C1 control characters, DEL, and the Unicode bidi/line-separator controls that can make a terminal
# show something other than what is stored (a reason that clears the screen or fakes a history line).
_CONTROL = {
    *range(0x00, 0x20),
    *range(0x7F, 0xA0),
    0x2028,
    0x2029,
    *range(0x202A, 0x202F),
    *range(0x2066, 0x206A),
}
_ESCAPES = {c: (f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}") for c in _CONTROL}


def plain(text: object) -> str:
    """Stored text as it may be printed: control characters shown as ``\\xNN`` / ``\\uNNNN`` escapes."""
    return str(text).translate(_ESCAPES)


def no_paint(colour: str, text: str) -> str:
    return text


def terminal_paint(colour: str, text: str) -> str:
    """``text`` in an ANSI colour on a terminal (as rich colours it), plain anywhere else or with NO_COLOR."""
    if os.environ.get("NO_COLOR") or not sys.stdout.isatty():
        return text
    return f"\x1b[{_ANSI[colour]}m{text}\x1b[0m"


def finding_lines(
    findings: Sequence[Finding],
    paint: Callable[[str, str], str] = no_paint,
    text: Callable[[object], str] = plain,
) -> list[str]:
    """The lines that show lint findings under a calibration ("  lint error rule: message", "fix: ...").
    ``paint(colour, word)`` colours the severity; ``text`` makes stored text printable (rich escapes markup
    too)."""
    if not findings:
        return [f"  lint: {paint('green', 'clean')}"]
    lines = []
    for f in findings:
        lines.append(
            f"  lint {paint(SEVERITY_COLOURS.get(f.severity, 'cyan'), f.severity)} {text(f.rule)}: "
            f"{text(f.message)}"
        )
        if f.fix and f.severity != "info":
            lines.append(f"       fix: {text(f.fix)}")
    return lines
