"""Output helpers shared by every command: results to stdout, diagnostics to stderr."""

from __future__ import annotations

import math
from typing import Any

from rich.console import Console, ConsoleDimensions
from rich.markup import escape as _escape_markup
from rich.rule import Rule

from calibctl.cli.plain_text import emit_json, plain
from calibctl.cli.streams import silence_closed_stdout

__all__ = ["LOG_WIDTH", "emit_json", "fmt_px", "plain", "shown", "stderr", "stdout"]

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


def say(line: str) -> None:
    """One result line on stdout, never wrapped or interpreted as markup (it holds URLs and user text)."""
    stdout.print(line, soft_wrap=True, markup=False, highlight=False)


def fmt_px(value: float | None, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


def shown(text: object) -> str:
    """``plain`` and with rich markup escaped: stored text for a line or table cell that rich renders."""
    return _escape_markup(plain(text))
