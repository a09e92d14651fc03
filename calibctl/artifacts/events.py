"""Activation events: the append-only log of which version of a serial is active, and why."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from calibctl.artifacts.common import Document, UtcDatetime


class ActivationEvent(Document):
    """One move of a serial's active version. Never updated, never deleted."""

    event_id: int = Field(ge=1, description="store-assigned, increasing")
    serial: str = Field(description="camera serial number")
    version: int = Field(ge=1, description="the version that became active")
    previous_version: int | None = Field(None, description="the version that was active before, if any")
    kind: Literal["activate", "rollback"] = Field(description="activate after a solve/import, or rollback")
    actor: str = Field(description="who did it")
    station: str = Field(description="where it was done")
    at: UtcDatetime = Field(description="UTC")
    reason: str = Field(min_length=1, description="why")
