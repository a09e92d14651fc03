"""`rig solve-folders` gives the stored path's verdict on its members: a camera the stored path would refuse
at capture or at lint is refused with the same rule's name, and a baseline far from ``--design-baseline-mm``
fails ``baseline-design``."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.config import LintThresholds
from calibctl.core.board.board_spec import BoardSpec
from calibctl.store.repository import Store
from calibctl.workflows.rig.rig_folders import solve_rig_folders
from tests.artifacts.factories import measured_board
from tests.workflows.rig_folders_data import rendered_rig, true_baseline_mm

RUNNER = CliRunner()
BOARD = BoardSpec.chessboard(9, 6, 0.025)


def invoke(*args: str):
    return RUNNER.invoke(app, list(args), terminal_width=110)


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


def _sources(cam0, cam1) -> list[str]:
    return [
        "--source",
        f"CAM0={cam0}",
        "--source",
        f"CAM1={cam1}",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square-mm",
        "25",
    ]


def test_a_member_the_stored_path_refuses_at_capture_is_refused_by_the_same_gate(rig2, tmp_path):
    """CAM1 with 7 of its 8 photos: capture's ``views`` gate (8) rejects its session, so ``solve`` refuses it;
    CAM0, all 8, passes capture and lint in both paths."""
    cam1 = tmp_path / "CAM1"
    shutil.copytree(rig2 / "CAM1", cam1)
    (cam1 / "CAM1_0007.png").unlink()
    url = f"sqlite:///{tmp_path / 'c.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board(square_mm=25.0))
    stored = RUNNER.invoke(
        app,
        ["--db", url, "--json", "capture", "--serial", "CAM1", "--board", "A17", "--source", str(cam1)],
        terminal_width=110,
    )
    assert stored.exit_code == 1, stored.output
    refused_by = {
        g["gate"]
        for g in json.loads(stored.stdout)["session"]["gates"]
        if not g["passed"] and not g.get("advisory")
    }
    assert "views" in refused_by  # with views failed there is no projection gate: coverage decides too

    result = invoke(
        "--json", "rig", "solve-folders", *_sources(rig2 / "CAM0", cam1), "--min-shared-views", "5"
    )
    assert result.exit_code == 1, result.output
    doc = json.loads(result.stdout)
    member = {(f["rule"], f["message"].split(":")[0]) for f in doc["lint"] if f["rule"].startswith("member:")}
    assert member == {(f"member:{gate}", "CAM1") for gate in refused_by}
    assert doc["verdict"] == "fail"


def test_a_member_lint_rule_applies_with_the_stations_limits(rig2):
    """The stored path lints every member's calibration (member:<rule>); so does solve-folders, same
    limits."""
    run = solve_rig_folders(
        {"CAM0": rig2 / "CAM0", "CAM1": rig2 / "CAM1"},
        BOARD,
        min_shared_views=5,
        limits=LintThresholds(sigma_fx_max_px=1e-6),
    )
    rules = sorted((f.rule, f.message.split(":")[0]) for f in run.findings)
    assert rules == [("member:sigma-fx", "CAM0"), ("member:sigma-fx", "CAM1")]
    assert not run.passed
    clean = solve_rig_folders({"CAM0": rig2 / "CAM0", "CAM1": rig2 / "CAM1"}, BOARD, min_shared_views=5)
    assert clean.passed and clean.findings == ()  # no square-size-provenance: solve-folders cannot apply it


def test_a_baseline_far_from_its_design_fails_baseline_design(rig2):
    true_mm = true_baseline_mm(rig2)
    far = invoke(
        "rig",
        "solve-folders",
        *_sources(rig2 / "CAM0", rig2 / "CAM1"),
        "--min-shared-views",
        "5",
        "--design-baseline-mm",
        f"CAM0:CAM1={true_mm - 5:.1f}+-1",
    )
    assert far.exit_code == 1, far.output
    assert "error baseline-design: CAM0-CAM1: baseline 75." in far.output and "check the mount" in far.output
    near = invoke(
        "rig",
        "solve-folders",
        *_sources(rig2 / "CAM0", rig2 / "CAM1"),
        "--min-shared-views",
        "5",
        "--design-baseline-mm",
        f"CAM0:CAM1={true_mm:.1f}+-1",
    )
    assert near.exit_code == 0, near.output


@pytest.mark.parametrize(
    ("design", "message"),
    [
        (
            "CAM0:CAM9=75+-1",
            "--design-baseline-mm CAM0:CAM9: name two different cameras of the rig (CAM0, CAM1)",
        ),
        ("CAM0-CAM1=75", "--design-baseline-mm must look like A:B=75.0+-0.5"),
    ],
)
def test_a_bad_design_baseline_exits_2_before_any_photo_is_read(tmp_path, design, message):
    result = invoke(
        "rig",
        "solve-folders",
        *_sources(tmp_path / "none0", tmp_path / "none1"),
        "--design-baseline-mm",
        design,
    )
    assert result.exit_code == 2, result.output
    assert message in result.output
