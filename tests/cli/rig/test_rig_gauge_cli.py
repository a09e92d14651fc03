"""`rig capture --reference-distance` and a failed gauge's board revision on the rig paths (seed chapter 0): a
rig captured or solved on a board revision whose gauge failed is refused until it is overridden with a reason,
and a rig whose members were calibrated with that revision is never active."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.workflows.rig.test_rig_store_flow import WHO
from tests.workflows.rig_folders_data import rendered_rig

RUNNER = CliRunner()
CAMS = ("CAM0", "CAM1")


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


@pytest.fixture(scope="module")
def fixture(rig2, tmp_path_factory):
    """A CAM0 photo of the rendered rig as the fixture picture, and its true camera-to-board distance (m)."""
    truth = json.loads((rig2 / "rig_truth.json").read_text())
    frame = next(f for f in truth["frames"] if "CAM0" in f["seen_by"])
    folder = tmp_path_factory.mktemp("rig-fixture")
    shutil.copy(rig2 / "CAM0" / f"CAM0_{frame['frame']:04d}.png", folder)
    T = np.array(frame["T_root_board"])
    centre = np.array([4 * 0.025, 2.5 * 0.025, 0.0])  # the rendered 9x6, 25 mm board's centre
    return folder, float(np.linalg.norm(T[:3, :3] @ centre + T[:3, 3]))


@pytest.fixture
def db(tmp_path, rig2):
    """Both members calibrated (accepted, active) with the 25 mm board registered as 23 mm: chapter 0."""
    url = f"sqlite:///{tmp_path / 'c.db'}"
    typo = measured_board("TYPO", square_mm=23.0)
    cameras = {
        c["name"]: np.array(c["K"]) for c in json.loads((rig2 / "rig_truth.json").read_text())["cameras"]
    }
    with Store.open(url) as store:
        store.add_board(measured_board(square_mm=25.0))
        store.add_board(typo)
        for name in CAMS:
            K = cameras[name]
            art = calibration(serial=name, fx=K[0, 0], cx=K[0, 2], cy=K[1, 2], board=typo)
            store.add_artifact(art, activate=True, **WHO)
    assert invoke(url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1").exit_code == 0
    return url


def invoke(db, *args):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


def _capture(db, rig2, board: str, *extra: str):
    sources = [a for c in CAMS for a in ("--source", f"{c}={rig2 / c}")]
    return invoke(db, "--json", "rig", "capture", "R1", "--board", board, *sources, *extra)


def _gauge_gate(done) -> dict:
    (gate,) = [g for g in json.loads(done.stdout)["rig_session"]["gates"] if g["gate"] == "metric-gauge"]
    return gate


def test_rig_capture_gauges_one_member_and_a_failure_binds_the_board(db, rig2, fixture) -> None:
    folder, true_m = fixture
    gauge = ("--reference-distance", f"{true_m:.4f}+-0.0005", "--reference-source", f"CAM0={folder}")
    done = _capture(db, rig2, "TYPO", *gauge)
    assert done.exit_code == 1, done.output
    out = json.loads(done.stdout)
    assert out["rig_session"]["status"] == "rejected"
    distance = out["camera_sessions"]["CAM0"]["metric_gauge"]["distance"]
    assert not distance["passed"] and distance["ratio"] == pytest.approx(0.92, abs=0.01)
    gate = _gauge_gate(done)
    assert not gate["passed"] and "board TYPO@1 failed its metric gauge" in gate["message"]
    assert "re-register the board with a measured span" in gate["hint"]
    # the failure is the board revision's now: a rig capture without a gauge is refused
    again = _capture(db, rig2, "TYPO")
    assert again.exit_code == 1 and not _gauge_gate(again)["passed"]
    right = _capture(db, rig2, "A17", *gauge)  # the same fixture through the right board passes
    assert right.exit_code == 0, right.output
    assert json.loads(right.stdout)["camera_sessions"]["CAM0"]["metric_gauge"]["distance"]["passed"]


def test_no_active_rig_from_members_calibrated_on_a_failed_board_even_when_the_capture_is_overridden(
    db, rig2, fixture
) -> None:
    folder, true_m = fixture
    gauge = ("--reference-distance", f"{true_m:.4f}+-0.0005", "--reference-source", f"CAM0={folder}")
    assert _capture(db, rig2, "TYPO", *gauge).exit_code == 1
    reason = "fixture re-surveyed; board replaced next shift"
    done = _capture(db, rig2, "TYPO", "--override-gauge", reason)
    assert done.exit_code == 0, done.output
    gate = _gauge_gate(done)
    assert gate["passed"] and gate["message"].endswith(f"overridden: {reason}")
    solved = invoke(db, "--json", "rig", "solve", "R1")
    assert solved.exit_code == 1, solved.output
    cal = json.loads(solved.stdout)
    assert cal["status"] == "rejected"
    rules = {f["rule"] for f in cal["lint"] if f["severity"] == "error"}
    assert rules == {"member:metric-gauge"}  # the capture's override is recorded; the members' is not
    with Store.open(db) as store:
        assert store.active_rig_version("R1") is None
    linted = invoke(db, "lint", "--serial", "CAM0")
    assert linted.exit_code == 1 and "board TYPO@1 failed its metric gauge" in linted.stdout


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (("--override-gauge", " "), "--override-gauge needs a reason"),
        (("--override-gauge", "why not"), "there is nothing to override"),
        (("--reference-distance", "0.5+-0.001", "--reference-source", "fixture"), "is not SERIAL=SRC"),
        (("--reference-distance", "0.5+-0.001", "--reference-source", "CAM9=f"), "not a camera of rig R1"),
        (("--reference-distance", "0.5+-0.001"), "go together"),
    ],
)
def test_bad_gauge_input_exits_2_naming_the_fix(db, rig2, extra, says) -> None:
    done = _capture(db, rig2, "A17", *extra)
    assert done.exit_code == 2, done.output
    assert says in done.stderr
    with Store.open(db) as store:
        assert store.list_sessions("CAM0") == []


@pytest.mark.parametrize(("square_mm", "passed"), [("23", False), ("25", True)])
def test_solve_folders_judges_the_gauge_through_a_members_own_lens(rig2, fixture, square_mm, passed) -> None:
    folder, true_m = fixture
    done = RUNNER.invoke(
        app,
        [
            "--json", "rig", "solve-folders", "--cols", "9", "--rows", "6", "--square-mm", square_mm,
            *(a for c in CAMS for a in ("--source", f"{c}={rig2 / c}")),
            "--reference-distance", f"{true_m:.4f}+-0.0005", "--reference-source", f"CAM0={folder}",
        ],
    )  # fmt: skip
    gauges = [f for f in json.loads(done.stdout)["lint"] if f["rule"] == "metric-gauge"]
    if passed:
        assert done.exit_code == 0 and gauges == [], done.output
        return
    assert done.exit_code == 1, done.output
    (finding,) = gauges
    assert finding["severity"] == "error" and finding["value"] == pytest.approx(0.92, abs=0.01)
    assert "every baseline is scaled by it" in finding["message"]
