"""Robot-arm hand-eye on a board revision whose metric gauge failed (seed chapter 0): every translation the
arm's photos give is scaled by the wrong square size, so the edge is rejected by a ``metric-gauge`` gate until
the camera's calibration overrides the failure with a recorded reason."""

from __future__ import annotations

from calibctl.artifacts.calibration import Provenance
from calibctl.config import load_settings
from calibctl.store.repository import Store
from calibctl.workflows.handeye.handeye_robot import run_robot_handeye
from tests.artifacts.factories import calibration, measured_board
from tests.store.documents import gauged_session
from tests.workflows.handeye.test_handeye_robot import scenes  # noqa: F401 - the shared rendered arm photos

WHO = {"actor": "qa", "station": "test", "reason": "renderer's camera"}


def _settings(url: str, override: str | None):
    art = calibration(cx=319.5, cy=239.5, board=measured_board())
    provenance: Provenance = art.provenance.model_copy(update={"gauge_override": override})
    with Store.open(url) as store:
        store.add_board(measured_board())
        store.add_artifact(art.model_copy(update={"provenance": provenance}), activate=True, **WHO)
        store.add_session(gauged_session("0000000000f1", 0.92, serial="CAM-0777"))  # A17@1 failed elsewhere
    return load_settings(db=url)


def test_a_board_whose_gauge_failed_rejects_the_hand_eye_edge(scenes, sqlite_url: str) -> None:  # noqa: F811
    d = scenes["in-hand"]
    result = run_robot_handeye(
        _settings(sqlite_url, None), d / "poses.csv", d, "CAM-0001", "gripper", "camera"
    ).result
    assert result.status == "rejected" and result.transform is None
    gate = result.gates[0]
    assert gate.gate == "metric-gauge" and not gate.passed
    assert "board A17@1 failed its metric gauge" in gate.message and "on CAM-0777" in gate.message
    assert gate.hint is not None and "calibrate CAM-0001 with --override-gauge REASON" in gate.hint


def test_a_calibration_that_overrode_the_failure_with_a_reason_lets_it_through(
    scenes,  # noqa: F811
    sqlite_url: str,
) -> None:
    d = scenes["in-hand"]
    reason = "fixture bent; board re-measured 25.00 mm"
    result = run_robot_handeye(
        _settings(sqlite_url, reason), d / "poses.csv", d, "CAM-0001", "gripper", "camera"
    ).result
    assert result.status == "accepted", [g.message for g in result.gates]
    gate = result.gates[0]
    assert gate.gate == "metric-gauge" and gate.passed and gate.message.endswith(f"CAM-0001@1: {reason}")


def test_a_passed_gauge_adds_no_gate(scenes, sqlite_url: str) -> None:  # noqa: F811
    d = scenes["in-hand"]
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(cx=319.5, cy=239.5, board=measured_board()), activate=True, **WHO)
        store.add_session(gauged_session("0000000000f2", 1.002))
    result = run_robot_handeye(
        load_settings(db=sqlite_url), d / "poses.csv", d, "CAM-0001", "gripper", "camera"
    ).result
    assert result.status == "accepted" and "metric-gauge" not in {g.gate for g in result.gates}
