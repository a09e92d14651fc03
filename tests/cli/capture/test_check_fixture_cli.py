"""`check --reference-distance` on a few pictures of the board in its fixture (seed chapter 0): the metric
gauge is judged from them while the statistical re-test keeps its 10-view rule, and the check says which part
it could not judge."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.synth.pinhole import PinholeCamera, render_view
from calibctl.core.synth.scenes import place_board, tilt_rotation
from calibctl.store.repository import Store
from tests.cli.capture.test_check_cli import BOARD, FIXTURE_DISTANCE_M, assets, db, invoke  # noqa: F401

# ruff: noqa: F811 - the shared fixtures are arguments of the tests below

GAUGE = ("--reference-distance", "0.450+-0.0005")


def _one_pose(out: Path, n: int, poses: int = 1) -> Path:
    """n pictures of the board in the fixture at FIXTURE_DISTANCE_M (tilted 25 deg), each a fresh exposure;
    ``poses`` > 1 turns the tilt between pictures (a folder that is not one fixture pose)."""
    camera = PinholeCamera.seed_reference((640, 480))
    out.mkdir(parents=True)
    rng = np.random.default_rng(11)
    centre = (float(camera.K[0, 2]), float(camera.K[1, 2]))
    for i in range(n):
        R = tilt_rotation(np.deg2rad(25.0), 2 * np.pi * (i % poses) / poses, 0.3)
        T = place_board(camera, BOARD, R, centre, FIXTURE_DISTANCE_M)
        cv2.imwrite(str(out / f"fixture{i:02d}.png"), render_view(camera, BOARD, T, rng))
    return out


@pytest.fixture(scope="module")
def pictures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("fixture-check")
    return {"one": _one_pose(root / "one", 3), "several": _one_pose(root / "several", 4, poses=4)}


def test_three_pictures_of_one_pose_catch_the_23mm_board(db: str, pictures) -> None:
    done = invoke(db, "check", "CAM-TYPO", "--source", str(pictures["one"]), *GAUGE, "--json")
    assert done.exit_code == 1, done.output
    event = json.loads(done.stdout)
    assert event["images"] == 3 and not event["passed"]  # one pose: the exposures are near-duplicates
    assert event["distance"]["ratio"] == pytest.approx(0.92, abs=0.004) and not event["distance"]["passed"]
    assert event["regions"] == [] and event["shifts"] == []  # the re-test did not run, and says so
    (part,) = event["not_judged"]
    assert part.startswith("the statistical re-test") and "it needs 10 views" in part
    with Store.open(db) as store:
        (stored,) = store.checks("CAM-TYPO")
    assert stored.not_judged == event["not_judged"] and not stored.passed


def test_the_right_board_passes_and_says_what_was_not_judged(db: str, pictures) -> None:
    done = invoke(db, "check", "CAM-GOOD", "--source", str(pictures["one"]), *GAUGE)
    assert done.exit_code == 0, done.output
    assert "ratio 1.00" in done.stdout and "not judged: the statistical re-test" in done.stdout


def test_ten_views_without_a_reference_say_the_gauge_was_not_judged(db: str, assets) -> None:
    done = invoke(db, "check", "CAM-GOOD", "--source", str(assets["fixture"]))
    assert done.exit_code == 0, done.output
    assert "distance  not judged: no --reference-distance" in done.stdout


def test_a_fixture_folder_of_several_poses_exits_2(db: str, pictures) -> None:
    done = invoke(db, "check", "CAM-TYPO", "--source", str(pictures["several"]), *GAUGE)
    assert done.exit_code == 2, done.output
    assert "show the board in several poses" in done.stderr and "only the pictures taken" in done.stderr
    with Store.open(db) as store:
        assert store.checks("CAM-TYPO") == []


def test_a_few_pictures_and_no_reference_exit_2_naming_both_fixes(db: str, pictures) -> None:
    done = invoke(db, "check", "CAM-GOOD", "--source", str(pictures["one"]))
    assert done.exit_code == 2, done.output
    assert "need at least 10" in done.stderr and "give --reference-distance" in done.stderr
