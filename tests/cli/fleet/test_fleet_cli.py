"""calibctl fleet add | assign | status: wiring, exit codes, --json, and refused steps."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


@pytest.fixture
def db(sqlite_url: str) -> str:
    """CAM-A @1 and @2 accepted (@2 active), @3 rejected; CAM-B @1 active."""
    with Store.open(sqlite_url, create=True) as store:
        for serial, status in (
            ("CAM-A", "accepted"),
            ("CAM-A", "accepted"),
            ("CAM-A", "rejected"),
            ("CAM-B", "accepted"),
        ):
            store.add_artifact(
                calibration(serial=serial, status=status), activate=status == "accepted", **WHO
            )
    return sqlite_url


def _run(db: str, *args: str):
    return CliRunner().invoke(app, ["--db", db, "fleet", *args])


def test_robots_their_versions_and_where_they_stand(db: str) -> None:
    assert _run(db, "status").stdout.startswith("no robots registered")
    added = _run(db, "add", "amr-1", "--serial", "CAM-A", "--serial", "CAM-B", "--reason", "commissioned")
    assert added.exit_code == 0 and "robot amr-1 registered: CAM-A, CAM-B" in added.stdout
    assigned = _run(db, "assign", "amr-1", "CAM-A@1", "--reason", "factory calibration")
    assert assigned.exit_code == 0 and "robot amr-1 runs CAM-A@1" in assigned.stdout
    text = _run(db, "status")
    assert text.exit_code == 0
    assert "CAM-A                runs @1     active @2     behind" in text.stdout
    assert "CAM-B                runs -      active @1     unassigned" in text.stdout
    doc = json.loads(_run(db, "status", "--json").stdout)
    assert doc["events"] == 2 and doc["robots"][0]["robot"] == "amr-1"
    assert [s["state"] for s in doc["robots"][0]["sensors"]] == ["behind", "unassigned"]
    assert _run(db, "assign", "amr-1", "CAM-A@2", "--reason", "recalibrated").exit_code == 0
    assert "current" in _run(db, "status").stdout
    verify = CliRunner().invoke(app, ["--db", db, "db", "verify"])
    assert verify.exit_code == 0, verify.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["assign", "amr-9", "CAM-A@1", "--reason", "x"], "robot amr-9 is not registered"),
        (
            ["assign", "amr-1", "CAM-A@3", "--reason", "x"],
            "CAM-A@3 is rejected: a robot must not run it, so it cannot be assigned",
        ),
        (["assign", "amr-1", "CAM-A", "--reason", "x"], "'CAM-A' names no version"),
        (["assign", "amr-1", "CAM-C@1", "--reason", "x"], "does not carry CAM-C"),
        (["assign", "amr-1", "CAM-A@1"], "a fleet change needs a reason"),
        (["add", "amr-1", "--serial", "CAM-A"], "robot amr-1 is already registered"),
        (["add", "amr-2"], "at least one camera serial or rig"),
        (["add", "bad name!", "--serial", "CAM-A"], "robot"),
    ],
)
def test_refused_steps_exit_2_and_write_nothing(db: str, args: list[str], message: str) -> None:
    assert _run(db, "add", "amr-1", "--serial", "CAM-A").exit_code == 0
    result = _run(db, *args)
    assert result.exit_code == 2, result.output
    assert message in result.stderr and "Traceback" not in result.output
    assert json.loads(_run(db, "status", "--json").stdout)["events"] == 1
