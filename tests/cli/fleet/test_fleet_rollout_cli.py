"""A rollout on a small fleet: a canary whose robot reports a failing check is held and rolled back in one
command, the rest never touched; a healthy canary is promoted; every step is in the chained log and
`db verify` passes; refused steps write nothing."""

from __future__ import annotations

import json

import pytest

from calibctl.artifacts.common import utc_now
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.cli.fleet.fleet_store import WHO, small_fleet
from tests.cli.fleet.fleet_store import run as _run
from tests.store.documents import check_event

ROBOTS = {"amr-1": "CAM-1", "amr-2": "CAM-2", "amr-3": "CAM-3"}


@pytest.fixture
def db(sqlite_url: str) -> str:
    """Three robots, one camera each: @1 runs everywhere, @2 is new (accepted), CAM-1@3 rejected."""
    small_fleet(sqlite_url, ROBOTS)
    with Store.open(sqlite_url) as store:
        store.add_artifact(calibration(serial="CAM-1", status="rejected"), activate=False, **WHO)
    return sqlite_url


def _start(db: str, name: str = "r1", canary: str = "amr-1"):
    return _run(
        db,
        "fleet",
        "rollout",
        "start",
        name,
        *(f"--target={s}@2" for s in ROBOTS.values()),
        "--canary",
        canary,
        "--reason",
        "new lens model",
        "--json",
    )


def _report(db: str, serial: str, n: int, passed: bool) -> None:
    with Store.open(db) as store:
        art = store.get_artifact(serial, 2)
        store.add_check(
            check_event(serial, 2, art.content_sha256, n, passed).model_copy(update={"at": utc_now()})
        )


def _running(db: str) -> dict[str, str]:
    doc = json.loads(_run(db, "fleet", "status", "--json").stdout)
    return {r["robot"]: r["sensors"][0]["running"] for r in doc["robots"]}


def test_a_failing_canary_is_held_and_rolled_back_the_rest_never_touched(db: str) -> None:
    started = _start(db)
    assert started.exit_code == 0, started.output
    doc = json.loads(started.stdout)
    assert doc["robots"] == {"amr-1": "canary", "amr-2": "pending", "amr-3": "pending"}
    # each target diffed against the version its robot runs: the factory's @1 and @2 are one lens without a
    # stored covariance, so the numbers are there and the verdict is not
    cam2 = doc["diffs"]["CAM-2"]
    assert cam2["previous"] == 1 and cam2["verdict"] == "unknown" and cam2["max_px"] < 1e-9
    assert _running(db) == {"amr-1": 2, "amr-2": 1, "amr-3": 1}
    early = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "hurry")
    assert early.exit_code == 2 and "amr-1 have no health report yet" in early.stderr
    _report(db, "CAM-1", 1, passed=False)
    held = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "looks fine")
    assert (
        held.exit_code == 1
        and "rollout r1 is held: canary robot(s) amr-1 report failing checks" in held.stderr
    )
    assert _running(db) == {"amr-1": 2, "amr-2": 1, "amr-3": 1}  # nothing promoted
    back = _run(db, "fleet", "rollout", "rollback", "r1", "--reason", "canary fails its check", "--json")
    assert back.exit_code == 0, back.output
    doc = json.loads(back.stdout)
    assert doc["closed"] == "rolled back"
    assert doc["robots"] == {"amr-1": "rolled back", "amr-2": "untouched", "amr-3": "untouched"}
    assert _running(db) == {"amr-1": 1, "amr-2": 1, "amr-3": 1}
    status = json.loads(_run(db, "fleet", "status", "--json").stdout)
    assert (
        status["events"] == 6 + 1 + 1 + 2
    )  # robots, the rollout and its canary, the rollback and its assign
    assert _run(db, "db", "verify").exit_code == 0
    again = _run(db, "fleet", "rollout", "rollback", "r1", "--reason", "twice")
    assert again.exit_code == 2 and "rolled back already" in again.stderr


def test_a_healthy_canary_is_promoted_to_the_rest_in_one_step(db: str) -> None:
    assert _start(db).exit_code == 0
    _report(db, "CAM-1", 1, passed=True)
    promoted = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "canary healthy", "--json")
    assert promoted.exit_code == 0, promoted.output
    assert json.loads(promoted.stdout)["robots"] == {
        "amr-1": "healthy",
        "amr-2": "promoted",
        "amr-3": "promoted",
    }
    assert _running(db) == {"amr-1": 2, "amr-2": 2, "amr-3": 2}
    text = _run(db, "fleet", "status").stdout
    assert "rollout r1 (promoted): CAM-1@2, CAM-2@2, CAM-3@2" in text
    assert _run(db, "db", "verify").exit_code == 0
    # a promoted rollout can still be rolled back, fleet-wide, in one command
    assert _run(db, "fleet", "rollout", "rollback", "r1", "--reason", "field reports").exit_code == 0
    assert _running(db) == {"amr-1": 1, "amr-2": 1, "amr-3": 1}


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["--target", "CAM-1@3", "--canary", "amr-1"], 2, "CAM-1@3 is rejected: a robot must not run it"),
        (["--target", "CAM-1@9", "--canary", "amr-1"], 2, "CAM-1 has no version 9"),
        (["--target", "CAM-1@2", "--canary", "amr-9"], 2, "canary robot amr-9 is not registered"),
        (
            ["--target", "CAM-1@2", "--canary", "amr-2"],
            2,
            "canary robot amr-2 carries none of the target serials",
        ),
        (["--target", "CAM-1", "--canary", "amr-1"], 2, "names no version"),
    ],
)
def test_bad_rollouts_exit_2_and_write_nothing(db: str, args: list[str], code: int, message: str) -> None:
    result = _run(db, "fleet", "rollout", "start", "bad", *args, "--reason", "x")
    assert result.exit_code == code, result.output
    assert message in result.stderr
    assert json.loads(_run(db, "fleet", "status", "--json").stdout)["events"] == 6


def test_a_robot_in_two_open_cohorts_is_refused(db: str) -> None:
    assert _start(db, "r1", "amr-1").exit_code == 0
    second = _run(
        db, "fleet", "rollout", "start", "r2", "--target", "CAM-1@2", "--canary", "amr-1", "--reason", "x"
    )
    assert (
        second.exit_code == 2 and "amr-1 is already in the canary cohort of open rollout r1" in second.stderr
    )
    unknown = _run(db, "fleet", "rollout", "promote", "nope", "--reason", "x")
    assert unknown.exit_code == 2 and "no rollout nope" in unknown.stderr
