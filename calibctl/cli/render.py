"""Output helpers shared by every command: results to stdout, diagnostics to stderr."""

from __future__ import annotations

import json
import math
from typing import Any

from rich.console import Console, ConsoleDimensions
from rich.markup import escape as _escape_markup
from rich.rule import Rule

from calibctl.cli.streams import silence_closed_stdout

LOG_WIDTH = 110
"""Width of rules when the output is not a terminal (a CI log, a pipe, a file)."""
_UNBOUNDED = 100_000  # tables lay out at their natural width: no cell is wrapped


class _Console(Console):
    """On a terminal, rich as usual (its width, wrapped). Anywhere else (a CI log, a pipe, a file) no
    line is ever broken, so ``grep`` finds every line whole: text soft-wraps and tables take their
    natural width; rules are LOG_WIDTH long."""

    @property
    def size(self) -> ConsoleDimensions:
        if self.is_terminal:
            return super().size
        return ConsoleDimensions(_UNBOUNDED, super().size.height)

    @size.setter
    def size(self, new_size: tuple[int, int]) -> None:
        Console.size.fset(self, new_size)  # type: ignore[attr-defined]

    def print(self, *objects: Any, **kwargs: Any) -> None:
        if not self.is_terminal:
            kwargs.setdefault("soft_wrap", True)
        super().print(*objects, **kwargs)

    def on_broken_pipe(self) -> None:
        # rich's default exits 1, which calibctl reserves for a "fail" verdict.
        self.quiet = True
        raise SystemExit(silence_closed_stdout())

    def rule(self, *args: Any, **kwargs: Any) -> None:
        if self.is_terminal:
            super().rule(*args, **kwargs)
        else:
            super().print(Rule(*args, **kwargs), width=LOG_WIDTH)


stdout = _Console(highlight=False)
stderr = _Console(highlight=False, stderr=True)


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


def fmt_px(value: float | None, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


# C0 and C1 control characters, DEL, and the Unicode bidi/line-separator controls that can make a terminal
# show something other than what is stored (a reason that clears the screen or fakes a history line).
_CONTROL = {*range(0x00, 0x20), *range(0x7F, 0xA0), 0x2028, 0x2029, *range(0x202A, 0x202F), *range(0x2066, 0x206A)}
_ESCAPES = {c: (f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}") for c in _CONTROL}


def plain(text: object) -> str:
    """Stored text as it may be printed: control characters shown as ``\\xNN`` / ``\\uNNNN`` escapes."""
    return str(text).translate(_ESCAPES)


def shown(text: object) -> str:
    """``plain`` and with rich markup escaped: stored text for a line or table cell that rich renders."""
    return _escape_markup(plain(text))
