"""The verdict every gate in core returns: capture gates, rig-frame checks and hand-eye gates alike.

It lives at the top of core, beside ``blas_threads``, because every capability room speaks it and no
room should import another just for the type.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class GateResult:
    """One gate. ``reason`` is a machine-readable code when it failed, ``hint`` tells the operator what to
    do."""

    gate: str
    passed: bool
    value: float
    threshold: float
    message: str
    reason: str | None = None
    hint: str | None = None
    detail: dict[str, float | int | str | list[str]] = field(default_factory=dict)
