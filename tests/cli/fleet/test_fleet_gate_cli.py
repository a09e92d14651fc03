"""A rollout's health gate reads the canary robots' own health reports: no report yet blocks promote (exit 2,
naming the robots), a failing check, gauge or triage holds it (exit 1, nothing applied); the promote records
the reports it decided on with their sha256 (``db verify`` re-checks them) and each target's diff against the
version it replaces."""

from __future__ import annotations

import json
import sqlite3
from datetime import timedelta
from pathlib import Path

import pytest

from calibctl.artifacts.common import utc_now
from calibctl.store.repository import Store
from tests.cli.fleet.fleet_store import run as _run
from tests.cli.fleet.fleet_store import small_fleet

ROBOTS = {"amr-1": "CAM-1", "amr-2": "CAM-2"}


@pytest.fixture
def db(sqlite_url: str) -> str:
    return small_fleet(sqlite_url, ROBOTS)


def _events(db: str) -> int:
    return json.loads(_run(db, "fleet", "status", "--json").stdout)["events"]


def _running(db: str) -> dict[str, int]:
    doc = json.loads(_run(db, "fleet", "status", "--json").stdout)
    return {r["robot"]: r["sensors"][0]["running"] for r in doc["robots"]}


def _ingest(db: str, path: Path, *reports: dict) -> None:
    now = utc_now()
    lines = [
        json.dumps(
            {
                "robot": "amr-1",
                "serial": "CAM-1",
                "time": (now + r.pop("shift", timedelta())).isoformat(),
                **r,
            }
        )
        for r in reports
    ]
    path.write_text("\n".join(lines) + "\n")
    result = _run(db, "fleet", "ingest", str(path))
    assert result.exit_code == 0, result.output


def _start(db: str) -> None:
    started = _run(
        db,
        "fleet",
        "rollout",
        "start",
        "r1",
        "--target",
        "CAM-1@2",
        "--target",
        "CAM-2@2",
        "--canary",
        "amr-1",
        "--reason",
        "new lens model",
    )
    assert started.exit_code == 0, started.output


def test_no_report_blocks_a_report_from_before_the_start_does_not_count(db: str, tmp_path: Path) -> None:
    _start(db)
    _ingest(
        db,
        tmp_path / "old.jsonl",
        {
            "source_id": "a1/old",
            "kind": "check",
            "rms_px": 0.2,
            "verdict": "pass",
            "shift": timedelta(hours=-1),
        },
    )
    _ingest(
        db,
        tmp_path / "td.jsonl",
        {"source_id": "a1/td", "kind": "timeoffset", "td_ms": 1.0, "sigma_ms": 0.1, "temperature_c": 20.0},
    )
    before = _events(db)
    early = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "hurry")
    assert early.exit_code == 2
    assert "canary robot(s) amr-1 have no health report yet (amr-1: CAM-1); nothing promoted" in early.stderr
    assert _events(db) == before and _running(db) == {"amr-1": 2, "amr-2": 1}
    assert "amr-1                canary (canary): no report on CAM-1" in _run(db, "fleet", "status").stdout


def test_a_report_stamped_in_the_rollouts_start_second_counts(db: str, tmp_path: Path) -> None:
    _start(db)
    with Store.open(db) as store:
        started = next(e for e in store.fleet_events() if e.kind == "rollout").at
    doc = {"source_id": "a1/start", "robot": "amr-1", "serial": "CAM-1", "kind": "check", "rms_px": 0.2}
    doc |= {
        "verdict": "pass",
        "time": started.replace(microsecond=0).isoformat(),
    }  # robots stamp whole seconds
    (tmp_path / "start.jsonl").write_text(json.dumps(doc) + "\n")
    assert _run(db, "fleet", "ingest", str(tmp_path / "start.jsonl")).exit_code == 0
    promoted = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "canary healthy", "--json")
    assert promoted.exit_code == 0, promoted.output
    assert [g["id"] for g in json.loads(promoted.stdout)["gate"]] == ["a1/start"]


@pytest.mark.parametrize(
    "report",
    [
        {"kind": "check", "rms_px": 2.5, "verdict": "fail"},
        {"kind": "gauge", "ratio": 1.02, "sigma": 0.001},
        {"kind": "triage", "verdict": "intrinsics"},
    ],
)
def test_a_failing_robot_report_holds_the_canary_nothing_applied(
    db: str, tmp_path: Path, report: dict
) -> None:
    _start(db)
    _ingest(
        db, tmp_path / "ok.jsonl", {"source_id": "a1/ok", "kind": "check", "rms_px": 0.2, "verdict": "pass"}
    )
    _ingest(db, tmp_path / "bad.jsonl", {"source_id": "a1/bad", **report})
    before = _events(db)
    held = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "looks fine")
    assert held.exit_code == 1, held.output
    assert (
        f"rollout r1 is held: canary robot(s) amr-1 report failing checks (amr-1: CAM-1 {report['kind']} "
        "report "
        "a1/bad: fail); nothing promoted" in held.stderr
    )
    assert _events(db) == before and _running(db) == {"amr-1": 2, "amr-2": 1}
    status = json.loads(_run(db, "fleet", "status", "--json").stdout)["rollouts"][0]
    assert status["robots"]["amr-1"] == "failed" and status["failing"]["amr-1"]
    assert _run(db, "fleet", "rollout", "rollback", "r1", "--reason", "canary report fails").exit_code == 0
    assert _running(db) == {"amr-1": 1, "amr-2": 1}
    assert _run(db, "db", "verify").exit_code == 0


def test_passing_reports_promote_and_the_promote_records_them_and_the_diff(db: str, tmp_path: Path) -> None:
    _start(db)
    _ingest(
        db,
        tmp_path / "ok.jsonl",
        {"source_id": "a1/check", "kind": "check", "rms_px": 0.2, "verdict": "pass"},
        {"source_id": "a1/gauge", "kind": "gauge", "ratio": 1.004, "sigma": 0.002},
        {"source_id": "a1/triage", "kind": "triage", "verdict": "ok"},
    )
    promoted = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "canary healthy", "--json")
    assert promoted.exit_code == 0, promoted.output
    doc = json.loads(promoted.stdout)
    assert doc["robots"] == {"amr-1": "healthy", "amr-2": "promoted"}
    assert sorted((g["id"], g["kind"], g["source"], g["passed"]) for g in doc["gate"]) == [
        ("a1/check", "check", "report", True),
        ("a1/gauge", "gauge", "report", True),
        ("a1/triage", "triage", "report", True),
    ]
    assert all(len(g["sha256"]) == 64 for g in doc["gate"])
    # each target against the version it replaces, recorded in the chained rollout event (the factory's @1 and
    # @2
    # are one lens: 0 px)
    assert doc["diffs"]["CAM-2"]["previous"] == 1 and doc["diffs"]["CAM-2"]["max_px"] < 1e-9
    assert _running(db) == {"amr-1": 2, "amr-2": 2}
    assert "promoted on 3 health input(s)" in _run(db, "fleet", "status").stdout
    assert _run(db, "db", "verify").exit_code == 0


def test_db_verify_catches_a_report_changed_after_the_promote_decided_on_it(db: str, tmp_path: Path) -> None:
    _start(db)
    _ingest(
        db,
        tmp_path / "ok.jsonl",
        {"source_id": "a1/check", "kind": "check", "rms_px": 0.2, "verdict": "pass"},
    )
    assert _run(db, "fleet", "rollout", "promote", "r1", "--reason", "ok").exit_code == 0
    path = db.removeprefix("sqlite:///")
    with sqlite3.connect(path) as con:  # an attacker with write access past the triggers
        con.execute("DROP TRIGGER trg_health_reports_no_update")
        con.execute(
            "UPDATE health_reports SET payload = replace(payload, '\"fail\"', '\"pass\"'), "
            "payload_sha256 = '" + "0" * 64 + "' WHERE source_id = 'a1/check'"
        )
    result = _run(db, "db", "verify")
    assert result.exit_code == 1
    assert "promote of rollout r1: its gate read report a1/check" in result.output
