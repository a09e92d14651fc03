"""Rigs as rollout targets: RIG@N targets; promote makes them their rigs' active versions and rollback
restores the previous ones, in the same transaction as the robots' assignments; a rig in two open rollouts,
an unknown rig, a rejected rig version and a rig whose active version moved are refused with nothing
written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.common import utc_now
from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.store.rig_documents import rig_calibration, rig_definition

RIGS = {"amr-1": "STEREO-1", "amr-2": "STEREO-2"}


@pytest.fixture
def db(sqlite_url: str) -> str:
    """Each robot its rig: @1 and @2 accepted (75 and 76 mm), @3 rejected; @2 is active after the solves."""
    with Store.open(sqlite_url, create=True) as store:
        for rig in RIGS.values():
            store.add_rig(rig_definition(rig))
            for status, baseline_m in (("accepted", 0.075), ("accepted", 0.076), ("rejected", 0.075)):
                store.add_rig_calibration(
                    rig_calibration(status, baseline_m).model_copy(update={"rig": rig}),
                    activate=status == "accepted",
                    actor="op",
                    station="st1",
                    reason="solved",
                )
            store.rollback_rig(rig, 1, reason="the fleet runs @1", actor="op", station="st1")
    for robot, rig in RIGS.items():
        assert _run(sqlite_url, "fleet", "add", robot, "--rig", rig).exit_code == 0
        assigned = _run(sqlite_url, "fleet", "assign", robot, f"{rig}@1", "--rig", "--reason", "factory")
        assert assigned.exit_code == 0, assigned.output
    return sqlite_url


def _run(db: str, *args: str):
    return CliRunner().invoke(app, ["--db", db, *args])


def _status(db: str) -> dict:
    return json.loads(_run(db, "fleet", "status", "--json").stdout)


def _state(db: str) -> tuple[dict[str, tuple[int, int]], int]:
    """robot -> (rig version it runs, the rig's active version); the log's length."""
    doc = _status(db)
    return {r["robot"]: (r["rigs"][0]["running"], r["rigs"][0]["active"]) for r in doc["robots"]}, doc[
        "events"
    ]


def _start(db: str, name: str = "r1", *targets: str) -> object:
    return _run(
        db,
        "fleet",
        "rollout",
        "start",
        name,
        *(targets or ("--rig-target=STEREO-1@2", "--rig-target=STEREO-2@2")),
        "--canary",
        "amr-1",
        "--reason",
        "re-solved rigs",
    )


def _report(db: str, path: Path, verdict: str = "pass") -> None:
    path.write_text(
        json.dumps(
            {
                "source_id": f"amr-1/rig/{verdict}",
                "robot": "amr-1",
                "serial": "STEREO-1",
                "time": utc_now().isoformat(),
                "kind": "check",
                "rms_px": 0.1,
                "verdict": verdict,
            }
        )
    )
    assert _run(db, "fleet", "ingest", str(path)).exit_code == 0


def test_a_rig_rollout_promotes_and_rolls_back_with_the_rigs_active_versions(db: str, tmp_path: Path) -> None:
    assert _start(db).exit_code == 0
    assert _state(db)[0] == {"amr-1": (2, 1), "amr-2": (1, 1)}
    text = _run(db, "fleet", "status").stdout
    assert "rollout r1: rig STEREO-1@2, rig STEREO-2@2" in text
    assert "  rig STEREO-1         runs @2     active @1     ahead" in text
    early = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "hurry")
    assert early.exit_code == 2 and "(amr-1: rig STEREO-1)" in early.stderr
    _report(db, tmp_path / "ok.jsonl")
    promoted = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "canary healthy", "--json")
    assert promoted.exit_code == 0, promoted.output
    doc = json.loads(promoted.stdout)
    assert doc["robots"] == {"amr-1": "healthy", "amr-2": "promoted"}
    assert doc["gate"][0]["rig"] and doc["gate"][0]["target"] == "STEREO-1"
    assert doc["diffs"]["rig STEREO-2"] == {
        "previous": 1,
        "verdict": "different",
        "p50_px": None,
        "max_px": None,
        "why": None,
    }  # 75 -> 76 mm, sigma 0.03 mm
    assert _state(db)[0] == {"amr-1": (2, 2), "amr-2": (2, 2)}
    assert _run(db, "db", "verify").exit_code == 0
    back = _run(db, "fleet", "rollout", "rollback", "r1", "--reason", "field reports")
    assert back.exit_code == 0, back.output
    assert _state(db)[0] == {"amr-1": (1, 1), "amr-2": (1, 1)}
    with Store.open(db) as store:
        kinds = [(e.kind, e.version, e.reason.split(":")[0]) for e in store.rig_events("STEREO-2")][-2:]
    assert kinds == [("activate", 2, "promoted by rollout r1"), ("rollback", 1, "rolled back by rollout r1")]
    assert _run(db, "db", "verify").exit_code == 0


def test_a_rollback_whose_rig_moved_since_the_promote_writes_nothing(db: str, tmp_path: Path) -> None:
    assert _start(db).exit_code == 0
    _report(db, tmp_path / "ok.jsonl")
    assert _run(db, "fleet", "rollout", "promote", "r1", "--reason", "ok").exit_code == 0
    with Store.open(db) as store:  # someone activates another version of one rig by hand meanwhile
        store.rollback_rig("STEREO-2", 1, reason="by hand", actor="op", station="st1")
        store.rollback_rig("STEREO-1", 1, reason="by hand", actor="op", station="st1")
        store.add_rig_calibration(
            rig_calibration("accepted", 0.077).model_copy(update={"rig": "STEREO-2"}),
            activate=True,
            actor="op",
            station="st1",
            reason="re-solved",
        )
    before = _state(db)
    back = _run(db, "fleet", "rollout", "rollback", "r1", "--reason", "field reports")
    assert back.exit_code == 2, back.output
    assert "rig STEREO-2: the active version changed underneath this rollback" in back.stderr
    assert _state(db) == before  # no robot's assignment written either: one transaction
    assert _run(db, "db", "verify").exit_code == 0


def test_a_failing_rig_report_holds_the_rig_rollout(db: str, tmp_path: Path) -> None:
    assert _start(db).exit_code == 0
    _report(db, tmp_path / "bad.jsonl", "fail")
    before = _state(db)
    held = _run(db, "fleet", "rollout", "promote", "r1", "--reason", "x")
    assert held.exit_code == 1 and "amr-1: STEREO-1 check report amr-1/rig/fail: fail" in held.stderr
    assert _state(db) == before


@pytest.mark.parametrize(
    ("targets", "message"),
    [
        (
            ("--rig-target=STEREO-9@1",),
            "canary robot amr-1 carries none of the target serials or rigs (it carries rig STEREO-1)",
        ),
        (("--rig-target=STEREO-1@3",), "rig STEREO-1@3 is rejected: a robot must not run it"),
        (("--rig-target=STEREO-1@7",), "rig STEREO-1 has no version 7"),
        (("--rig-target=STEREO-1",), "names no version"),
        (("--rig-target=STEREO-1@2", "--rig-target=STEREO-1@1"), "rig STEREO-1 is targeted twice"),
        (("--target=STEREO-1@2",), "carries none of the target serials or rigs"),  # a serial, not the rig
    ],
)
def test_bad_rig_targets_exit_2_and_write_nothing(db: str, targets: tuple[str, ...], message: str) -> None:
    before = _state(db)
    result = _start(db, "bad", *targets)
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    assert _state(db) == before


def test_a_rig_in_two_open_rollouts_is_refused(db: str) -> None:
    assert _start(db).exit_code == 0
    before = _state(db)
    second = _run(
        db,
        "fleet",
        "rollout",
        "start",
        "r2",
        "--rig-target",
        "STEREO-2@2",
        "--canary",
        "amr-2",
        "--reason",
        "x",
    )
    assert second.exit_code == 2
    assert (
        "rig STEREO-2@2: rig STEREO-2 is a target of open rollout r1 already (rig STEREO-2@2)"
        in second.stderr
    )
    assert _state(db) == before
    wrong = _run(db, "fleet", "assign", "amr-1", "STEREO-2@1", "--rig", "--reason", "x")
    assert wrong.exit_code == 2 and "robot amr-1 does not carry rig STEREO-2" in wrong.stderr


def test_an_unknown_rig_is_refused_by_name(db: str) -> None:
    assert _run(db, "fleet", "add", "amr-3", "--rig", "STEREO-9").exit_code == 0
    before = _state(db)
    result = _run(
        db,
        "fleet",
        "rollout",
        "start",
        "r9",
        "--rig-target",
        "STEREO-9@1",
        "--canary",
        "amr-3",
        "--reason",
        "x",
    )
    assert result.exit_code == 2 and "rig STEREO-9 has no calibration yet" in result.stderr
    assert _state(db) == before
