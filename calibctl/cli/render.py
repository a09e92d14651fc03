"""Output helpers shared by every command: results to stdout, diagnostics to stderr."""

from __future__ import annotations

import json
import math
from typing import Any

from rich.console import Console, ConsoleDimensions
from rich.rule import Rule

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
