"""The fleet's log: robots (named units that carry sensors) and which calibration version each runs.

One append-only, hash-chained, signed stream of ``FleetEvent`` documents for the whole store (the
store's ``fleet_events`` table); a robot's state is the replay of its events. ``register`` names a
robot and the camera serials and rigs it carries; ``assign`` records that the robot now runs
``serial@version`` (``rollout`` names the rollout that made it). A rollout is staged like a deploy:
``rollout`` names new versions for a set of serials and a canary cohort of robots (their assignments
follow in the same transaction), ``promote`` gives the rest of the fleet theirs once the canary is
healthy, ``rollback`` puts every robot the rollout touched back on the version it ran before.
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
    kind: Literal["register", "assign", "rollout", "promote", "rollback"] = Field(
        description="register a robot; assign it a calibration version; start, promote or roll back a rollout")
    robot: str | None = Field(None, pattern=ROBOT_PATTERN, description="register, assign: the robot (letters, "
                              "digits, . _ : -)")
    serials: list[str] = Field(default_factory=list, description="register: camera serials the robot carries")
    rigs: list[str] = Field(default_factory=list, description="register: rigs the robot carries")
    serial: str | None = Field(None, pattern=SERIAL_PATTERN, description="assign: the camera serial")
    version: int | None = Field(None, ge=1, le=MAX_VERSION, description="assign: the calibration version it now runs")
    rollout: str | None = Field(None, pattern=ROBOT_PATTERN, description="rollout, promote, rollback: the rollout's "
                                "name; assign: the rollout that made it, if any")
    targets: dict[str, int] = Field(default_factory=dict, description="rollout: serial -> the new version")
    canary: list[str] = Field(default_factory=list, description="rollout: the robots that get it first")
    actor: str = Field(min_length=1, description="who did it")
    station: str = Field(min_length=1, description="where it was done")
    at: UtcDatetime = Field(description="UTC")
    reason: str = Field(min_length=1, description="why")

    @property
    def subject(self) -> str:
        """The robot (register, assign) or the rollout (the rollout kinds) the event is about."""
        subject = self.robot if self.kind in ("register", "assign") else self.rollout
        assert subject is not None  # the validator's promise
        return subject

    @model_validator(mode="after")
    def _shape(self) -> FleetEvent:
        if (self.robot is None) == (self.kind in ("register", "assign")):
            raise ValueError("register and assign name a robot; the rollout kinds name a rollout and no robot")
        if self.kind not in ("register", "assign") and self.rollout is None:
            raise ValueError(f"{self.kind} names its rollout")
        if self.kind == "register":
            if not (self.serials or self.rigs):
                raise ValueError("a robot carries at least one camera serial or rig")
            if self.serial is not None or self.version is not None or self.rollout is not None:
                raise ValueError("register names serials and rigs, not one serial@version")
            for names in (self.serials, self.rigs):
                if len(set(names)) != len(names):
                    raise ValueError("a serial or rig is listed twice")
        elif self.kind == "assign":
            if self.serial is None or self.version is None or self.serials or self.rigs or self.targets or self.canary:
                raise ValueError("assign names one serial and version, nothing else")
        elif self.kind == "rollout":
            if not self.targets or not self.canary:
                raise ValueError("a rollout names target versions and a canary cohort")
            if len(set(self.canary)) != len(self.canary):
                raise ValueError("a canary robot is listed twice")
        elif self.serials or self.rigs or self.targets or self.canary or self.serial is not None:
            raise ValueError(f"{self.kind} names the rollout only")
        return self
