"""A small fleet for the rollout tests: robots with one camera each, @1 and @2 accepted, every robot on @1."""

from __future__ import annotations

from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


def run(db: str, *args: str):
    return CliRunner().invoke(app, ["--db", db, *args])


def small_fleet(url: str, robots: dict[str, str]) -> str:
    """``robots``: robot -> its camera serial; each serial gets @1 and @2 (accepted), each robot runs @1."""
    with Store.open(url, create=True) as store:
        for serial in robots.values():
            for _ in range(2):
                store.add_artifact(calibration(serial=serial, status="accepted"), activate=True, **WHO)
    for robot, serial in robots.items():
        assert run(url, "fleet", "add", robot, "--serial", serial).exit_code == 0
        assert run(url, "fleet", "assign", robot, f"{serial}@1", "--reason", "factory").exit_code == 0
    return url
