"""The capture-time distance gauge judges through the lens model the session will be solved with.

A session and fixture pictures are rendered through the SAME 150 deg equidistant fisheye, the board
centre FISHEYE_FIXTURE_M from the camera: through the fisheye lens the gauge recovers that distance;
through k1k2 (what the gauge used for every model before) the same board lands far outside 0.99-1.01;
``--model auto`` gauges through the model it chooses.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.config import Settings, load_settings
from calibctl.errors import NumericalError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.board.boards import board_spec
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.camera.capture import CaptureRequest, CaptureResult, capture
from calibctl.workflows.camera.distance_gauge import (
    RATIO_LIMITS,
    ReferenceDistance,
    detect_fixture_views,
    gauge_capture,
    gauge_model,
)
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import FISHEYE_FIXTURE_M, fisheye_gauge_folders

SURVEY = ReferenceDistance(FISHEYE_FIXTURE_M, 0.0003)
RIGHT_LENS_TOL = 0.003  # the brief's bar for the right lens: within 0.3 % of the surveyed distance


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return fisheye_gauge_folders(tmp_path_factory)


@pytest.fixture(scope="module")
def settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    url = f"sqlite:///{tmp_path_factory.mktemp('gauge') / 'calibctl.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return load_settings(db=url, station="st-7", operator="op-ana", env={})


@pytest.fixture(scope="module")
def captured(settings: Settings, folders: tuple[Path, Path]) -> CaptureResult:
    """The fisheye session captured with the gauge solving through the fisheye lens."""
    session, fixture = folders
    return capture(
        settings,
        CaptureRequest(
            "FE-0007",
            "A17",
            str(session),
            reference_distance=SURVEY,
            reference_source=str(fixture),
            gauge_model="fisheye",
        ),
    )


def test_a_fisheye_board_is_gauged_through_the_fisheye_lens_and_k1k2_would_fail_it(
    captured: CaptureResult, folders: tuple[Path, Path]
) -> None:
    result = captured
    session = result.session
    assert session.status == "accepted" and len(session.views) == 10  # every rendered view detected
    spec = board_spec(session.board)
    found, examined = detect_fixture_views(
        spec, session.board.ref, sources.resolve_source(str(folders[1])), (640, 480), "this session"
    )
    assert len(found) == examined == 4
    assert result.distance is not None and result.distance.passed and result.passed
    assert result.distance.ratio == pytest.approx(1.0, abs=RIGHT_LENS_TOL)
    # the old gauge: the same session and fixture through a k1k2 lens fail a correct board
    k1k2, lens = gauge_capture(
        SURVEY, str(folders[1]), spec, session.board.ref, session.views, (640, 480), "k1k2"
    )
    assert lens == "k1k2" and not k1k2.passed and abs(k1k2.ratio - 1.0) > RATIO_LIMITS[1] - 1.0
    # auto: through the model `solve --model auto` chooses on these corners (not k1k2), and the board passes
    auto, lens = gauge_capture(
        SURVEY, str(folders[1]), spec, session.board.ref, session.views, (640, 480), "auto"
    )
    assert lens != "k1k2" and auto.passed


def test_a_session_the_model_cannot_solve_exits_2_naming_the_gauge_and_the_model(
    captured: CaptureResult, folders: tuple[Path, Path]
) -> None:
    session = captured.session
    two = session.views[:2]  # fewer than any model needs
    with pytest.raises(NumericalError) as raised:
        gauge_capture(
            SURVEY, str(folders[1]), board_spec(session.board), session.board.ref, two, (640, 480), "fisheye"
        )
    assert raised.value.exit_code == 2
    assert raised.value.message.startswith(
        "the distance gauge cannot judge this session: its 2 views do not "
        "solve with the fisheye lens model (model fisheye needs at least 3"
    )
    assert raised.value.hint is not None and "--model" in raised.value.hint


@pytest.mark.parametrize(
    ("model", "lens"), [("fisheye", "fisheye"), ("rational", "rational"), ("auto", "auto"), (None, "k1k2")]
)
def test_the_gauge_solves_with_the_model_asked_for_and_k1k2_without_one(model: str | None, lens: str) -> None:
    assert gauge_model(model) == lens


def test_an_unknown_gauge_model_is_a_usage_error_before_anything_is_read(
    settings: Settings, tmp_path: Path
) -> None:
    with pytest.raises(UsageError, match="unknown distortion model 'fish'") as raised:
        capture(settings, CaptureRequest("FE-0007", "A17", str(tmp_path / "nowhere"), gauge_model="fish"))
    assert raised.value.exit_code == 2
    with pytest.raises(UsageError, match="unknown distortion model 'fish'"):
        gauge_model("fish")
