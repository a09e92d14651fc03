"""Tilt on real photos (../shared/datasets), against the tilt of a plain OpenCV solve of the same files."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture.detect import detect_board
from calibctl.core.capture.gates import evaluate_gates
from calibctl.core.capture.tilt import normal_tilt_direction
from tests.datasets import LEFT_RIGHT, require_datasets

BOARD = BoardSpec.chessboard(9, 6, 1.0)
AGREE_DEG = 2.0  # the gate's lens model is smaller than a full solve: c at the centre, no k3, no tangential


def plain_tilts(paths) -> dict[str, float]:
    """Tilt per file from cv2.findChessboardCorners + cornerSubPix + cv2.calibrateCamera (flags 0)."""
    names, obj, img, size = [], [], [], None
    for path in paths:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        size = (gray.shape[1], gray.shape[0])
        found, corners = cv2.findChessboardCorners(
            gray, (9, 6), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        )
        if not found:
            continue
        corners = cv2.cornerSubPix(
            gray, corners, (11, 11), (-1, -1), (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
        )
        names.append(path.name)
        obj.append(BOARD.object_points().astype(np.float32))
        img.append(corners.reshape(-1, 2))
    _, _, _, rvecs, _ = cv2.calibrateCamera(obj, img, size, None, None)
    return {n: normal_tilt_direction(np.ravel(r))[0] for n, r in zip(names, rvecs, strict=True)}


@pytest.mark.parametrize("camera", ["left", "right"])
def test_gate_tilt_agrees_with_a_plain_opencv_solve_on_real_photos(camera: str) -> None:
    require_datasets()
    paths = sorted(LEFT_RIGHT.glob(f"{camera}*.jpg"))
    views, size = [], None
    for path in paths:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        size = (gray.shape[1], gray.shape[0])
        det, _ = detect_board(gray, BOARD)
        if det is not None:
            views.append(BoardView(path.name, det.corner_ids, det.corners_px))
    report = evaluate_gates(views, BOARD.object_points(), size)
    plain = plain_tilts(paths)
    common = [g for g in report.views if g.name in plain]
    assert len(common) >= 10
    diffs = [abs(g.tilt_deg - plain[g.name]) for g in common]
    assert max(diffs) < AGREE_DEG, dict(zip([g.name for g in common], diffs, strict=True))
