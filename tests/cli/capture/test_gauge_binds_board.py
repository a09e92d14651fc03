"""A failed metric gauge binds its board revision (seed chapter 0): once the 23-mm-for-25 board failed a
gauge, no later calibration on that revision becomes active, whichever camera and whether or not it is gauged
again, until the board is re-registered with a measured span or the failure is overridden with a reason."""

from __future__ import annotations

import json

import pytest

from calibctl.store.repository import Store
from tests.cli.capture.test_check_cli import assets, db, invoke  # noqa: F401 - the shared rendered fixtures

GAUGE = ("--reference-distance", "0.450+-0.0005")
SPAN_25 = (
    "--square-mm", "25", "--uncertainty-mm", "0.02", "--instrument", "calipers", "--measured-by", "qa",
    "--measured-on", "2026-11-20", "--span-mm", "200", "--span-uncertainty-mm", "0.1",
    "--span-instrument", "steel rule",
)  # fmt: skip


def _fail_the_gauge(db: str, assets) -> None:
    done = invoke(
        db, "capture", "--serial", "CAM-NEW", "--board", "TYPO", "--source", str(assets["good"]), *GAUGE,
        "--reference-source", str(assets["fixture"]),
    )  # fmt: skip
    assert done.exit_code == 1, done.output


def _calibrate(db: str, assets, serial: str, *extra: str):
    return invoke(
        db,
        "calibrate",
        "--serial",
        serial,
        "--board",
        "TYPO",
        "--source",
        str(assets["good"]),
        "--json",
        *extra,
    )


def _gauge_finding(art: dict) -> dict:
    (finding,) = [f for f in art["lint"] if f["rule"] == "metric-gauge"]
    return finding


def test_a_later_calibration_on_the_failed_board_is_stored_rejected_and_never_active(db: str, assets) -> None:
    _fail_the_gauge(db, assets)
    done = _calibrate(db, assets, "CAM-LATER")  # another camera, no gauge asked for
    assert done.exit_code == 1, done.output
    art = json.loads(done.stdout)["calibration"]
    assert art["status"] == "rejected"
    finding = _gauge_finding(art)
    assert finding["severity"] == "error"
    assert "board TYPO@1 failed its metric gauge" in finding["message"] and "on CAM-NEW" in finding["message"]
    assert "0.920x the surveyed 0.4500 m" in finding["message"]
    assert "re-register the board with a measured span" in finding["fix"]
    assert "--override-gauge REASON" in finding["fix"]
    with Store.open(db) as store:
        assert store.active_version("CAM-LATER") is None


def test_lint_names_a_calibration_made_before_its_board_failed_a_gauge(db: str, assets) -> None:
    assert invoke(db, "lint", "--serial", "CAM-TYPO").exit_code == 0  # nothing known against it yet
    _fail_the_gauge(db, assets)
    done = invoke(db, "lint", "--serial", "CAM-TYPO", "--json")
    assert done.exit_code == 1, done.output
    out = json.loads(done.stdout)
    (result,) = out["results"] if isinstance(out, dict) else out
    (finding,) = [f for f in result["findings"] if f["rule"] == "metric-gauge"]
    assert "board TYPO@1 failed its metric gauge" in finding["message"]
    assert invoke(db, "lint", "--serial", "CAM-GOOD").exit_code == 0  # another board: untouched


def test_a_failed_check_side_gauge_binds_the_board_too(db: str, assets) -> None:
    check = invoke(db, "check", "CAM-TYPO", "--source", str(assets["fixture"]), *GAUGE)
    assert check.exit_code == 1, check.output
    done = _calibrate(db, assets, "CAM-LATER")
    assert done.exit_code == 1, done.output
    message = _gauge_finding(json.loads(done.stdout)["calibration"])["message"]
    assert "check " in message and "of CAM-TYPO@1 on CAM-TYPO" in message


def test_an_override_with_a_reason_is_recorded_and_kept_as_a_warning(db: str, assets) -> None:
    _fail_the_gauge(db, assets)
    reason = "fixture bracket bent; gauge invalid until re-survey"
    done = _calibrate(db, assets, "CAM-LATER", "--override-gauge", reason)
    assert done.exit_code == 0, done.output
    art = json.loads(done.stdout)["calibration"]
    assert art["status"] == "accepted" and art["provenance"]["gauge_override"] == reason
    finding = _gauge_finding(art)
    assert finding["severity"] == "warning" and finding["message"].endswith(f"overridden: {reason}")
    linted = invoke(db, "lint", "--serial", "CAM-LATER")
    assert linted.exit_code == 0, linted.output


@pytest.mark.parametrize("reason", ["", "  "])
def test_an_override_without_a_reason_exits_2_and_nothing_is_stored(db: str, assets, reason: str) -> None:
    _fail_the_gauge(db, assets)
    done = _calibrate(db, assets, "CAM-LATER", "--override-gauge", reason)
    assert done.exit_code == 2 and "--override-gauge needs a reason" in done.stderr
    with Store.open(db) as store:
        assert store.list_sessions("CAM-LATER") == []


def test_re_registering_with_a_measured_span_clears_the_board(db: str, assets) -> None:
    _fail_the_gauge(db, assets)
    added = invoke(db, "board", "add", "TYPO", "--cols", "9", "--rows", "6", *SPAN_25)
    assert added.exit_code == 0, added.output
    done = _calibrate(db, assets, "CAM-LATER")  # TYPO is now TYPO@2, 25 mm measured
    assert done.exit_code == 0, done.output
    art = json.loads(done.stdout)["calibration"]
    assert art["board"]["revision"] == 2 and art["status"] == "accepted"
    assert not [f for f in art["lint"] if f["rule"] == "metric-gauge"]


def test_a_re_registration_that_changes_nothing_exits_2_naming_the_fix(db: str, assets) -> None:
    _fail_the_gauge(db, assets)
    bare = invoke(db, "board", "add", "TYPO", "--cols", "9", "--rows", "6", "--square-mm", "23")
    assert bare.exit_code == 2 and "without a measured span cannot clear it" in bare.stderr
    assert "--span-mm" in bare.stderr
    same = [a if a != "25" else "23" for a in SPAN_25]
    same[same.index("200")] = "184"  # a span that agrees with 23 mm squares
    again = invoke(db, "board", "add", "TYPO", "--cols", "9", "--rows", "6", *same)
    assert again.exit_code == 2 and "changes nothing" in again.stderr and "--override-gauge" in again.stderr
    with Store.open(db) as store:
        assert store.board_revisions("TYPO") == [1]
