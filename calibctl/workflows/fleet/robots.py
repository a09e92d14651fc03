"""``calibctl fleet add | assign | status``: robots, the calibration version each runs, and where that
stands against the store's active versions. Every step is a ``FleetEvent`` in the store's chained log."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from calibctl import bounded
from calibctl.artifacts.common import utc_now, validation_message
from calibctl.artifacts.fleet import FleetEvent
from calibctl.config import Settings
from calibctl.errors import UsageError
from calibctl.workflows.store_admin import records

if TYPE_CHECKING:
    from calibctl.store.fleet_ledger import Fleet


def fleet_event(**fields: Any) -> FleetEvent:
    try:
        return FleetEvent(**fields)
    except ValidationError as exc:
        raise UsageError(
            validation_message(exc, "the fleet event"), "check the robot name and the serials"
        ) from None


def new_fleet_event(kind: str, settings: Settings, reason: str, **fields: Any) -> FleetEvent:
    """A fleet event by the settings' operator at its station, now."""
    return fleet_event(
        kind=kind, actor=settings.operator, station=settings.station, at=utc_now(), reason=reason, **fields
    )


def _record(settings: Settings, event: FleetEvent) -> FleetEvent:
    with records.open_store(settings, write=True) as store:
        store.add_fleet_event(event)
    return event


def check_reason(reason: str) -> None:
    if not reason.strip():
        raise UsageError("a fleet change needs a reason", "pass --reason 'why'")
    bounded.check_text(reason, "--reason", "the reason")


def add_robot(settings: Settings, robot: str, serials: list[str], rigs: list[str], reason: str) -> FleetEvent:
    """Register ``robot`` carrying ``serials`` and ``rigs`` (AlreadyExistsError when it is registered)."""
    check_reason(reason)
    return _record(
        settings, new_fleet_event("register", settings, reason, robot=robot, serials=serials, rigs=rigs)
    )


def assign(settings: Settings, robot: str, ref: str, reason: str, *, rig: bool = False) -> FleetEvent:
    """Record that ``robot`` now runs ``SERIAL@N`` (``rig``: ``RIG@N``), an accepted, stored version of a
    serial (rig) it carries."""
    check_reason(reason)
    name, version = records.parse_artifact_ref(ref)
    if version is None:
        raise UsageError(f"'{ref}' names no version", f"assign an explicit version, e.g. {name}@3")
    subject = {"rig": name} if rig else {"serial": name}
    return _record(
        settings, new_fleet_event("assign", settings, reason, robot=robot, **subject, version=version)
    )


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
        return (
            "current"
            if self.running == self.active
            else ("behind" if self.running < self.active else "ahead")
        )


@dataclass
class RobotState:
    robot: str
    rigs: list[SensorState]  # ``serial`` holds the rig's name
    sensors: list[SensorState] = field(default_factory=list)
    registered_at: str = ""


@dataclass
class FleetStatus:
    robots: list[RobotState]
    events: int

    def as_json(self) -> dict[str, Any]:
        def one(s: SensorState, key: str) -> dict[str, Any]:
            return {key: s.serial, "running": s.running, "active": s.active, "state": s.state}

        return {
            "events": self.events,
            "robots": [
                {
                    "robot": r.robot,
                    "rigs": [one(s, "rig") for s in r.rigs],
                    "registered_at": r.registered_at,
                    "sensors": [one(s, "serial") for s in r.sensors],
                }
                for r in self.robots
            ],
        }


def robot_states(fleet: Fleet, serial_active: dict[str, int], rig_active: dict[str, int]) -> FleetStatus:
    """Each robot of the replayed log, its serials and rigs, the version each runs against the active one."""
    robots = []
    for robot, carried in fleet.carries.items():
        states = {
            kind: [
                SensorState(name, fleet.running.get((robot, (kind, name))), active.get(name))
                for k, name in carried
                if k == kind
            ]
            for kind, active in (("serial", serial_active), ("rig", rig_active))
        }
        robots.append(RobotState(robot, states["rig"], states["serial"], fleet.registered_at[robot]))
    return FleetStatus(sorted(robots, key=lambda r: r.robot), fleet.length)
