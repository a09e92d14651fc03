"""Automatic frame selection on synthetic video: keep still, new views; skip moving and repeated ones."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import Detection, detect_chessboard
from calibctl.core.capture.frame_select import (
    ADDS_NOTHING,
    BLURRED,
    KEPT,
    MOVING,
    NEAR_DUPLICATE,
    NO_BOARD,
    FrameSelector,
    SelectorSettings,
    tilt_band,
)
from calibctl.core.capture.gates import GateThresholds
from calibctl.core.synth.pinhole import PinholeCamera, true_corners_px
from calibctl.core.synth.scenes import video_plan
from calibctl.workflows.synth.synth import load_truth, run_synth

BOARD = BoardSpec.chessboard(9, 6, 0.025)
CAMERA = PinholeCamera.seed_reference()
IDS = np.arange(BOARD.n_corners)


def truth_detection(T: np.ndarray, edge_width_px: float = 2.5) -> Detection:
    return Detection(IDS, true_corners_px(CAMERA, BOARD, T), "truth", edge_width_px)


def run_plan(n_keys: int, seed: int = 0) -> tuple[FrameSelector, list]:
    plan = video_plan(CAMERA, BOARD, n_keys, np.random.default_rng(seed))
    selector = FrameSelector(BOARD, CAMERA.image_size)
    decisions = [selector.offer(i, truth_detection(T)) for i, T in enumerate(plan.poses)]
    return selector, list(zip(plan.still, plan.key_index, decisions, strict=True))


def test_one_still_frame_is_kept_per_key_pose_and_never_a_moving_one() -> None:
    selector, rows = run_plan(10)
    kept = [(still, key) for still, key, d in rows if d.kept]
    assert all(still for still, _ in kept)
    keys = [key for _, key in kept]
    assert len(keys) == len(set(keys)) >= 8  # at most one frame per pause; min_views reached
    for key in set(range(10)) - set(keys):  # a pause that brought nothing new was seen and declined
        assert ADDS_NOTHING in [d.status for still, k, d in rows if k == key]
    for still, _, d in rows:
        if not still:
            assert d.status == MOVING and d.motion_px is not None
            # it read "board moving (156.4 px since the previous frame, still below 2.4 px)"
            assert (
                re.fullmatch(
                    r"board moving: \d+\.\d px since the previous frame \(still is under \d+\.\d px\)",
                    d.reason,
                )
                or d.reason == "board not seen in the previous frame"
            ), d.reason
    # the first frame of each pause follows motion, the ones after the kept frame repeat it
    statuses = [d.status for still, _, d in rows if still]
    assert statuses[:4] == [MOVING, KEPT, NEAR_DUPLICATE, NEAR_DUPLICATE]
    progress = selector.progress()
    assert progress.n_views == len(keys)
    assert all(all(row) for row in progress.covered)
    assert len(progress.directions) >= 3
    assert progress.observability > progress.observability_min
    assert progress.missing == ()


def test_live_view_names_what_is_missing_early_on() -> None:
    selector, rows = run_plan(2)
    progress = selector.progress()
    assert progress.n_views == 2
    assert progress.observability < progress.observability_min
    text = " | ".join(progress.missing)
    assert "tilt the board toward the" in text and "cover the" in text and "capture 6 more views" in text


def test_a_kept_view_says_what_it_added() -> None:
    _, rows = run_plan(3)
    first = next(d for _, _, d in rows if d.kept)
    assert any(a.startswith("covers the ") for a in first.adds)
    assert any(a.startswith("tilt ") and "toward the" in a for a in first.adds)


def test_frames_without_a_board_or_blurred_are_skipped_and_break_stillness() -> None:
    plan = video_plan(CAMERA, BOARD, 1, np.random.default_rng(1), still_frames=4, move_frames=0)
    selector = FrameSelector(BOARD, CAMERA.image_size)
    d0 = selector.offer(0, truth_detection(plan.poses[0]))
    d1 = selector.offer(1, None)
    d2 = selector.offer(2, truth_detection(plan.poses[2], edge_width_px=12.0))
    d3 = selector.offer(3, truth_detection(plan.poses[3]))
    assert [d.status for d in (d0, d1, d2, d3)] == [MOVING, NO_BOARD, BLURRED, KEPT]
    assert d0.reason == "board not seen in the previous frame"


def test_still_views_that_add_nothing_are_declined_once_min_views_is_reached() -> None:
    selector, _ = run_plan(12)
    # replay each kept pose twice (kept), then nudged by 1.5 px: still, not a duplicate at this
    # tighter duplicate limit, but it brings no new cell or pose bin
    settings = SelectorSettings(near_duplicate_frac=0.001, thresholds=GateThresholds(min_views=3))
    again = FrameSelector(BOARD, CAMERA.image_size, settings)
    nudged_decisions = []
    for i, view in enumerate(selector.kept):
        det = Detection(IDS, view.corners_px, "truth", 2.5)
        again.offer(3 * i, det)
        assert again.offer(3 * i + 1, det).kept
        nudged_decisions.append(again.offer(3 * i + 2, Detection(IDS, view.corners_px + 1.5, "truth", 2.5)))
    assert nudged_decisions[0].kept and nudged_decisions[0].reason == "view 2 of the 3 needed"
    assert all(d.status == ADDS_NOTHING for d in nudged_decisions[3:])
    assert nudged_decisions[3].reason == "adds no coverage or tilt the session lacks"


@pytest.mark.parametrize(
    ("tilt", "band"), [(0.0, 0), (9.99, 0), (10.0, 1), (25.0, 2), (30.0, 3), (45.0, 3), (46.0, 4)]
)
def test_tilt_bands(tilt: float, band: int) -> None:
    assert tilt_band(tilt) == band


def test_selection_on_a_rendered_video_file(tmp_path: Path) -> None:
    """The whole path: synth writes an MJPG video, frames are read back, detected and selected."""
    result = run_synth(tmp_path / "vid", "video", seed=3, views=3, image_size=(320, 240))
    truth = load_truth(result.truth_path)
    capture = cv2.VideoCapture(str(tmp_path / "vid" / "video.avi"))
    selector = FrameSelector(BOARD, (320, 240))
    decisions = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
        det, _ = detect_chessboard(gray, BOARD.cols, BOARD.rows)
        decisions.append(selector.offer(len(decisions), det))
    capture.release()
    frames = truth["views"]
    assert len(decisions) == len(frames)
    kept = [frames[d.index] for d in decisions if d.kept]
    assert [f["key_pose"] for f in kept] == [0, 1, 2]
    assert all(f["still"] for f in kept)


def test_a_frames_tilt_is_read_through_the_lens_the_gates_fitted() -> None:
    """Once progress() has a lens, a near-flat board at the image edge reads near-flat (through a pinhole
    the seed lens' barrel distortion reads as several degrees of tilt)."""
    from calibctl.core.synth.scenes import place_board, tilt_rotation

    selector, _ = run_plan(10)
    selector.progress()
    T = place_board(CAMERA, BOARD, tilt_rotation(np.radians(2.0), 0.5, 0.0), (560.0, 80.0), 0.45)
    still = truth_detection(T)
    selector.offer(1000, still)
    decision = selector.offer(1001, still)  # the second still frame: judged on what it adds
    assert decision.tilt_deg is not None and abs(decision.tilt_deg - 2.0) < 1.0
    few = Detection(IDS[:6], still.corners_px[:6], "truth", 2.5)  # a 6-corner partial view has no tilt
    selector.offer(1002, few)
    assert selector.offer(1003, few).tilt_deg is None
