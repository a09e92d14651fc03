"""The fleet's log: robots (named units that carry sensors) and which calibration version each runs.

One append-only, hash-chained, signed stream of ``FleetEvent`` documents for the whole store (the
store's ``fleet_events`` table); a robot's state is the replay of its events. ``register`` names a
robot and the camera serials and rigs it carries; ``assign`` records that the robot now runs
``serial@version``. Rollouts (canary, health gate, promote, rollback; issue 25 item 2) add kinds here.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from calibctl.artifacts.common import MAX_VERSION, SERIAL_PATTERN, Document, UtcDatetime

FLEET_EVENT_SCHEMA_VERSION: Literal[1] = 1
ROBOT_PATTERN = SERIAL_PATTERN


class FleetEvent(Document):
    """One step of the fleet's log. Never updated, never deleted."""

    schema_version: Literal[1] = Field(FLEET_EVENT_SCHEMA_VERSION, description="version of this document's schema")
    kind: Literal["register", "assign"] = Field(description="register a robot, or assign it a calibration version")
    robot: str = Field(pattern=ROBOT_PATTERN, description="robot name (letters, digits, . _ : -)")
    serials: list[str] = Field(default_factory=list, description="register: camera serials the robot carries")
    rigs: list[str] = Field(default_factory=list, description="register: rigs the robot carries")
    serial: str | None = Field(None, pattern=SERIAL_PATTERN, description="assign: the camera serial")
    version: int | None = Field(None, ge=1, le=MAX_VERSION, description="assign: the calibration version it now runs")
    actor: str = Field(min_length=1, description="who did it")
    station: str = Field(min_length=1, description="where it was done")
    at: UtcDatetime = Field(description="UTC")
    reason: str = Field(min_length=1, description="why")

    @model_validator(mode="after")
    def _shape(self) -> FleetEvent:
        if self.kind == "register":
            if not (self.serials or self.rigs):
                raise ValueError("a robot carries at least one camera serial or rig")
            if self.serial is not None or self.version is not None:
                raise ValueError("register names serials and rigs, not one serial@version")
            for names in (self.serials, self.rigs):
                if len(set(names)) != len(names):
                    raise ValueError("a serial or rig is listed twice")
        elif self.serial is None or self.version is None or self.serials or self.rigs:
            raise ValueError("assign names one serial and version, nothing else")
        return self
