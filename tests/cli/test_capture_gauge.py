"""`calibctl capture --reference-distance`: the gauge at capture catches the 23 mm typo before any solve (seed chapter 0)."""

from __future__ import annotations

import json

import pytest

from calibctl.errors import NotFoundError
from calibctl.store.repository import Store
from tests.cli.test_check_cli import assets, db, invoke  # noqa: F401 - the shared rendered fixtures

GAUGE = ("--reference-distance", "0.450+-0.0005")


def _capture(db: str, assets, board: str, *extra: str):  # noqa: F811
    return invoke(db, "capture", "--serial", "CAM-NEW", "--board", board, "--source", str(assets["good"]), *extra)


def test_a_board_registered_at_23mm_passes_the_gates_and_fails_the_gauge(db: str, assets) -> None:  # noqa: F811
    done = _capture(db, assets, "TYPO", *GAUGE, "--reference-source", str(assets["fixture"]))
    assert done.exit_code == 1, done.output
    assert "ratio 0.920" in done.stdout and "FAIL" in done.stdout
    assert "the metric scale is wrong (board square size?); the residual cannot show it" in done.stdout
    with Store.open(db) as store:
        (session,) = store.list_sessions("CAM-NEW")
    assert session.status == "accepted"  # every gate passed: only the gauge sees it


def test_the_right_board_passes_the_gauge_and_says_so_in_json(db: str, assets) -> None:  # noqa: F811
    done = _capture(db, assets, "A17", *GAUGE, "--reference-source", str(assets["fixture"]), "--json")
    assert done.exit_code == 0, done.output
    out = json.loads(done.stdout)
    assert out["passed"] and out["distance"]["passed"]
    assert out["distance"]["ratio"] == pytest.approx(1.0, abs=0.004)


@pytest.mark.parametrize("extra", [GAUGE, ("--reference-source", "fixture")])
def test_the_distance_and_its_pictures_go_together(db: str, assets, extra: tuple[str, ...]) -> None:  # noqa: F811
    done = _capture(db, assets, "A17", *extra)
    assert done.exit_code == 2
    assert "--reference-distance and --reference-source go together" in done.stderr


def test_fixture_pictures_of_another_size_exit_2_naming_both(db: str, assets) -> None:  # noqa: F811
    done = _capture(db, assets, "A17", *GAUGE, "--reference-source", str(assets["small"]))
    assert done.exit_code == 2
    assert "are not 640x480, the size this session was calibrated at" in done.stderr and "(320x240)" in done.stderr


def test_calibrate_does_not_solve_a_session_whose_gauge_failed(db: str, assets) -> None:  # noqa: F811
    done = invoke(db, "calibrate", "--serial", "CAM-NEW", "--board", "TYPO", "--source", str(assets["good"]),
                  *GAUGE, "--reference-source", str(assets["fixture"]))
    assert done.exit_code == 1, done.output
    assert "ratio 0.920" in done.stdout and "not solved: the distance gauge failed" in done.stdout
    # no calibration was stored
    with Store.open(db) as store, pytest.raises(NotFoundError, match="unknown serial 'CAM-NEW'"):
        store.list_artifacts("CAM-NEW")
