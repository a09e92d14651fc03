"""``calibctl fleet add | assign | status``: robots, the calibration version each runs, and where that
stands against the store's active versions. Every step is a ``FleetEvent`` in the store's chained log."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pydantic import ValidationError

from calibctl import bounded
from calibctl.artifacts.common import utc_now, validation_message
from calibctl.artifacts.fleet import FleetEvent
from calibctl.config import Settings
from calibctl.errors import UsageError
from calibctl.workflows.store_admin import records


def fleet_event(**fields: Any) -> FleetEvent:
    try:
        return FleetEvent(**fields)
    except ValidationError as exc:
        raise UsageError(validation_message(exc, "the fleet event"), "check the robot name and the serials") from None


def check_reason(reason: str) -> None:
    if not reason.strip():
        raise UsageError("a fleet change needs a reason", "pass --reason 'why'")
    bounded.check_text(reason, "--reason", "the reason")


def add_robot(settings: Settings, robot: str, serials: list[str], rigs: list[str], reason: str) -> FleetEvent:
    """Register ``robot`` carrying ``serials`` and ``rigs`` (AlreadyExistsError when it is registered)."""
    check_reason(reason)
    event = fleet_event(kind="register", robot=robot, serials=serials, rigs=rigs, actor=settings.operator,
                   station=settings.station, at=utc_now(), reason=reason)
    with records.open_store(settings, write=True) as store:
        store.add_fleet_event(event)
    return event


def assign(settings: Settings, robot: str, ref: str, reason: str) -> FleetEvent:
    """Record that ``robot`` now runs ``SERIAL@N`` (an accepted, stored version of a serial it carries)."""
    check_reason(reason)
    serial, version = records.parse_artifact_ref(ref)
    if version is None:
        raise UsageError(f"'{ref}' names no version", f"assign an explicit version, e.g. {serial}@3")
    event = fleet_event(kind="assign", robot=robot, serial=serial, version=version, actor=settings.operator,
                   station=settings.station, at=utc_now(), reason=reason)
    with records.open_store(settings, write=True) as store:
        store.add_fleet_event(event)
    return event


@dataclass
class SensorState:
    """One serial on one robot: the version it runs (None: never assigned) and the store's active one."""

    serial: str
    running: int | None
    active: int | None

    @property
    def state(self) -> str:
        if self.running is None:
            return "unassigned"
        if self.active is None:
            return "no active version"
        return "current" if self.running == self.active else ("behind" if self.running < self.active else "ahead")


@dataclass
class RobotState:
    robot: str
    rigs: list[str]
    sensors: list[SensorState] = field(default_factory=list)
    registered_at: str = ""


@dataclass
class FleetStatus:
    robots: list[RobotState]
    events: int

    def as_json(self) -> dict[str, Any]:
        return {"events": self.events, "robots": [
            {"robot": r.robot, "rigs": r.rigs, "registered_at": r.registered_at,
             "sensors": [{"serial": s.serial, "running": s.running, "active": s.active, "state": s.state}
                         for s in r.sensors]} for r in self.robots]}


def status(settings: Settings) -> FleetStatus:
    """Replay the fleet log: each robot, its sensors, the version each runs against the active one."""
    with records.open_store(settings) as store:
        events = store.fleet_events()
        robots: dict[str, RobotState] = {}
        running: dict[tuple[str, str], int] = {}
        for e in events:
            if e.kind == "register":
                robots[e.subject] = RobotState(e.subject, list(e.rigs), registered_at=e.at.isoformat())
                robots[e.subject].sensors = [SensorState(s, None, None) for s in e.serials]
            elif e.kind == "assign" and e.serial is not None and e.version is not None:
                running[(e.subject, e.serial)] = e.version
        serials = sorted({s.serial for r in robots.values() for s in r.sensors})
        active = {s: store.active_version(s) for s in serials}
    for r in robots.values():
        for s in r.sensors:
            s.running, s.active = running.get((r.robot, s.serial)), active.get(s.serial)
    return FleetStatus(sorted(robots.values(), key=lambda r: r.robot), len(events))
