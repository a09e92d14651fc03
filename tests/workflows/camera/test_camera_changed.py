"""A camera that changed during the session is refused at the solve, not blended (renders through the real
detector: the seed lens at 640x480, its focal length 1 % longer or its principal point 3 px away from the
tenth of 20 views on)."""

from __future__ import annotations

import pytest

from calibctl.artifacts.session import CaptureSession
from calibctl.config import Settings, load_settings
from calibctl.workflows.camera.solve import SolveRequest, build_artifact
from tests.artifacts.factories import measured_board
from tests.workflows.sessions import CHANGE_AT, changed_capture

HINT = "check the lens lock and focus, then capture again"


@pytest.fixture(scope="module")
def settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    url = f"sqlite:///{tmp_path_factory.mktemp('changed') / 'c.db'}"
    return load_settings(db=url, station="st-test", operator="tester", env={})


@pytest.fixture(scope="module")
def sessions() -> dict[str, CaptureSession]:
    board = measured_board(square_mm=25.0)
    return {
        "clean": changed_capture(board, 100),
        "focal": changed_capture(board, 201, focal=0.01),
        "centre": changed_capture(board, 300, centre=(3.0, 0.0)),
    }


@pytest.mark.parametrize(
    ("case", "moved"), [("focal", "focal moved by +1.0"), ("centre", "principal point by 3")]
)
def test_a_changed_camera_is_stored_rejected_with_the_hint(sessions, settings, case: str, moved: str) -> None:
    art, _ = build_artifact(sessions[case], SolveRequest(), settings)
    assert art.status == "rejected"
    (finding,) = [f for f in art.lint if f.rule == "camera-changed"]
    assert finding.severity == "error" and "this calibration is a blend" in finding.message
    assert finding.fix is not None and finding.fix.startswith("the camera changed during the session (")
    assert moved in finding.fix and finding.fix.endswith(HINT)
    change = art.camera_change
    assert change is not None and change.changed and abs(change.views[0] - CHANGE_AT) <= 1


def test_a_clean_session_is_not_called_changed(sessions, settings) -> None:
    art, _ = build_artifact(sessions["clean"], SolveRequest(), settings)
    assert art.camera_change is not None and not art.camera_change.changed
    assert not [f for f in art.lint if f.rule == "camera-changed"]
