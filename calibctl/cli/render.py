"""Output helpers shared by every command: results to stdout, diagnostics to stderr."""

from __future__ import annotations

import json
import math
from typing import Any

from rich.console import Console

# Fixed width keeps reports stable in logs and in CliRunner tests; rich still wraps long tables.
stdout = Console(width=110, highlight=False, soft_wrap=False)
stderr = Console(width=110, highlight=False, stderr=True)


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
