"""On a real paper board that is not flat (udacity-camcal: DATASET.md gives mrcal's warp), the gate judges the
covariance calibctl reports and names the board, not the lens model or the views, as the cause."""

from __future__ import annotations

import cv2
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import detect_board
from calibctl.core.capture.projection_gate import (
    PROJECTION_SIGMA_MAX_PX,
    Region,
    cause_first,
    projection_gate,
    solve_for_gate,
)
from tests.core.intrinsics.test_solve_real import _natural
from tests.datasets import UDACITY, needs_datasets

pytestmark = [pytest.mark.slow, needs_datasets]
BOARD = BoardSpec.chessboard(9, 6, 0.025)
SIZE = (1280, 720)


def test_a_real_bowed_paper_board_is_named_with_its_fix() -> None:
    obj, img = [], []
    for path in sorted(UDACITY.glob("calibration*.jpg"), key=_natural):
        found, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), BOARD)
        if found is not None:
            obj.append(BOARD.object_points()[found.corner_ids])
            img.append(found.corners_px)
    solution = solve_for_gate(obj, img, SIZE, None)
    gate = projection_gate(solution, SIZE, Region("image"), PROJECTION_SIGMA_MAX_PX)
    assert not gate.passed and "view-level x" in gate.message  # refused at the sigma calibctl reports
    named = cause_first(gate, solution, obj, img, SIZE, Region("image"), PROJECTION_SIGMA_MAX_PX)
    assert named.reason == "projection.board_not_flat"
    assert named.hint is not None and named.hint.startswith("the board is not flat")
    assert "with the bow solved the calibration predicts the whole image to" in named.hint
