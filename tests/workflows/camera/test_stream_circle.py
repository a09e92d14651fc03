"""A video or live camera capture without --image-circle finds the circle in the frames seen so far, so its
stop decision (the live gates) counts coverage inside a circular fisheye's image circle; a pinhole stream
keeps the nine cells."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.config import load_settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.store.repository import Store
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.camera.capture import CIRCLE_EVERY_FRAMES, _StreamState
from calibctl.workflows.synth.synth import run_synth
from tests.workflows.synth_folders import rendered

SPEC = BoardSpec.chessboard(9, 6, 0.025)
TOLERANCE_PX = 3.0


def _feed(tmp_path: Path, frames: list[np.ndarray]) -> _StreamState:
    settings = load_settings(
        db=f"sqlite:///{tmp_path / 's.db'}", station="st-test", operator="tester", env={}
    )
    with Store.open(settings.db_url) as store:
        state = _StreamState(store, settings, SPEC)
        for i, image in enumerate(frames):
            state.take(sources.Frame(i, image, i / 10.0))
    return state


def test_a_fisheye_stream_counts_live_coverage_inside_the_circle_it_finds(tmp_path: Path) -> None:
    out = tmp_path / "r190"
    run_synth(out, "good", seed=5, views=12, image_size=(640, 480), fisheye_fov_deg=190.0)
    truth = json.loads((out / "truth.json").read_text())["camera"]
    # each view held for three frames: the selector keeps a board once it is still
    frames = [image for p in sorted(out.glob("view-*.png")) for image in [cv2.imread(str(p))] * 3]
    assert len(frames) >= CIRCLE_EVERY_FRAMES
    state = _feed(tmp_path, frames)
    assert state.selector is not None and state.progress is not None and state.selector.kept
    circle = state.selector.settings.image_circle
    assert circle is not None and circle.source == "detected"
    assert abs(circle.cx_px - truth["K"][0][2]) < TOLERANCE_PX
    assert abs(circle.radius_px - truth["image_circle_px"]) < TOLERANCE_PX
    coverage = state.progress.report.gate("coverage")
    assert coverage.threshold == 5 and coverage.detail["image_circle_source"] == "detected"


def test_a_pinhole_stream_finds_no_circle_and_keeps_the_nine_cells(
    tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
) -> None:
    video = cv2.VideoCapture(str(rendered(tmp_path_factory, "video") / "video.avi"))
    frames = []
    while len(frames) < 3 * CIRCLE_EVERY_FRAMES:
        ok, image = video.read()
        if not ok:
            break
        frames.append(image)
    video.release()
    assert len(frames) >= CIRCLE_EVERY_FRAMES
    state = _feed(tmp_path, frames)
    assert state.selector is not None and state.selector.settings.image_circle is None
    if state.progress is not None and state.selector.kept:
        assert state.progress.report.gate("coverage").threshold == 9
