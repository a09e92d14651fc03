"""The fleet's log: robots (named units that carry sensors) and which calibration version each runs.

One append-only, hash-chained, signed stream of ``FleetEvent`` documents for the whole store (the
store's ``fleet_events`` table); a robot's state is the replay of its events. ``register`` names a
robot and the camera serials and rigs it carries; ``assign`` records that the robot now runs
``serial@version`` (``rollout`` names the rollout that made it). A rollout is staged like a deploy:
``rollout`` names new versions for a set of serials and a canary cohort of robots (their assignments
follow in the same transaction), ``promote`` gives the rest of the fleet theirs once the canary is
healthy, ``rollback`` puts every robot the rollout touched back on the version it ran before.

A target is a camera serial's version or a rig's (``rig_targets``; an ``assign`` names ``serial`` or ``rig``).
A ``rollout`` records each target's diff against the version its robots ran (``diffs``, ``rig_diffs``); a
``promote`` records what its health gate decided on (``gate``: each report's id and sha256, so the decision
can be re-checked against the stored reports) and, for rigs it activated, the version that was active before
(``restore``, what a rollback puts back).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from calibctl.artifacts.common import MAX_VERSION, SERIAL_PATTERN, Document, UtcDatetime

FLEET_EVENT_SCHEMA_VERSION: Literal[1] = 1
ROBOT_PATTERN = SERIAL_PATTERN


class GateEvidence(Document):
    """One health report a promote's gate decided on: a stored ``calibctl check`` or a robot's health
    report."""

    robot: str = Field(pattern=ROBOT_PATTERN, description="the canary robot it is about")
    target: str = Field(pattern=SERIAL_PATTERN, description="the target serial or rig it is about")
    rig: bool = Field(False, description="target names a rig")
    source: Literal["check", "report"] = Field(
        description="check: a stored check event (check_events); report: a "
        "robot's health report (health_reports)"
    )
    id: str = Field(min_length=1, max_length=128, description="the check id or the report's source id")
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$", description="the stored row's payload sha256")
    kind: str = Field(min_length=1, max_length=16, description="check, gauge or triage")
    passed: bool = Field(description="what the gate read from it")


class TargetDiff(Document):
    """A target's ``calibctl diff`` against the version its robots ran before, as the promote saw it."""

    previous: int = Field(ge=1, le=MAX_VERSION, description="the version it replaces")
    verdict: str = Field(min_length=1, max_length=32, description="same, different, unknown or not compared")
    p50_px: float | None = Field(None, description="cameras: median projection difference, px")
    max_px: float | None = Field(None, description="cameras: largest projection difference, px")
    why: str | None = Field(None, max_length=500, description="not compared: why")


class FleetEvent(Document):
    """One step of the fleet's log. Never updated, never deleted."""

    schema_version: Literal[1] = Field(
        FLEET_EVENT_SCHEMA_VERSION, description="version of this document's schema"
    )
    kind: Literal["register", "assign", "rollout", "promote", "rollback"] = Field(
        description="register a robot; assign it a calibration version; start, promote or roll back a rollout"
    )
    robot: str | None = Field(
        None, pattern=ROBOT_PATTERN, description="register, assign: the robot (letters, digits, . _ : -)"
    )
    serials: list[str] = Field(default_factory=list, description="register: camera serials the robot carries")
    rigs: list[str] = Field(default_factory=list, description="register: rigs the robot carries")
    serial: str | None = Field(None, pattern=SERIAL_PATTERN, description="assign: the camera serial")
    rig: str | None = Field(None, pattern=SERIAL_PATTERN, description="assign: the rig (instead of a serial)")
    version: int | None = Field(
        None, ge=1, le=MAX_VERSION, description="assign: the calibration version it now runs"
    )
    rollout: str | None = Field(
        None,
        pattern=ROBOT_PATTERN,
        description="rollout, promote, rollback: the rollout's "
        "name; assign: the rollout that made it, if any",
    )
    targets: dict[str, int] = Field(default_factory=dict, description="rollout: serial -> the new version")
    rig_targets: dict[str, int] = Field(default_factory=dict, description="rollout: rig -> the new version")
    canary: list[str] = Field(default_factory=list, description="rollout: the robots that get it first")
    gate: list[GateEvidence] = Field(
        default_factory=list, description="promote: the reports its health gate read"
    )
    diffs: dict[str, TargetDiff] = Field(
        default_factory=dict,
        description="rollout: serial target -> its diff against the version its robots ran",
    )
    rig_diffs: dict[str, TargetDiff] = Field(
        default_factory=dict, description="rollout: rig target -> its diff"
    )
    restore: dict[str, int] = Field(
        default_factory=dict,
        description="promote: rig -> its active version before the "
        "promote activated the target (a rollback restores it)",
    )
    actor: str = Field(min_length=1, description="who did it")
    station: str = Field(min_length=1, description="where it was done")
    at: UtcDatetime = Field(description="UTC")
    reason: str = Field(min_length=1, description="why")

    @property
    def target(self) -> tuple[str, str]:
        """assign: ("serial", SERIAL) or ("rig", RIG), what the robot now runs a version of."""
        return ("serial", self.serial) if self.serial is not None else ("rig", str(self.rig))

    @property
    def subject(self) -> str:
        """The robot (register, assign) or the rollout (the rollout kinds) the event is about."""
        subject = self.robot if self.kind in ("register", "assign") else self.rollout
        assert subject is not None  # the validator's promise
        return subject

    @model_validator(mode="after")
    def _shape(self) -> FleetEvent:
        if (self.robot is None) == (self.kind in ("register", "assign")):
            raise ValueError(
                "register and assign name a robot; the rollout kinds name a rollout and no robot"
            )
        if self.kind not in ("register", "assign") and self.rollout is None:
            raise ValueError(f"{self.kind} names its rollout")
        if self.kind == "register":
            if not (self.serials or self.rigs):
                raise ValueError("a robot carries at least one camera serial or rig")
            if (
                self.serial is not None
                or self.rig is not None
                or self.version is not None
                or self.rollout is not None
            ):
                raise ValueError("register names serials and rigs, not one serial@version")
            for names in (self.serials, self.rigs):
                if len(set(names)) != len(names):
                    raise ValueError("a serial or rig is listed twice")
        elif self.kind == "assign":
            if (
                (self.serial is None) == (self.rig is None)
                or self.version is None
                or self.serials
                or self.rigs
                or self.targets
                or self.rig_targets
                or self.canary
            ):
                raise ValueError("assign names one serial or one rig and its version, nothing else")
        elif self.kind == "rollout":
            if not (self.targets or self.rig_targets) or not self.canary:
                raise ValueError("a rollout names target versions and a canary cohort")
            if len(set(self.canary)) != len(self.canary):
                raise ValueError("a canary robot is listed twice")
        elif (
            self.serials
            or self.rigs
            or self.targets
            or self.rig_targets
            or self.canary
            or self.serial is not None
            or self.rig is not None
        ):
            raise ValueError(f"{self.kind} names the rollout only")
        if self.kind != "promote" and (self.gate or self.restore):
            raise ValueError("only a promote records its gate and restore versions")
        if self.kind != "rollout" and (self.diffs or self.rig_diffs):
            raise ValueError("only a rollout records its targets' diffs")
        return self
