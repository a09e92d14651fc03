"""ChArUco variants real targets use: inverted markers (white on black), the legacy layout, the dictionary as
declared; a declaration that never matches is named with what the frames show instead."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import charuco_variant_advice, charuco_variant_counts, detect_board
from calibctl.core.synth.pinhole import PinholeCamera, render_view, true_corners_px
from calibctl.core.synth.scenes import place_board, tilt_rotation

CAMERA = PinholeCamera.seed_reference()
INVERTED = BoardSpec.charuco(5, 7, 0.03, 0.0225, "DICT_4X4_1000", inverted=True)
LEGACY = BoardSpec.charuco(
    5, 6, 0.03, 0.0225, "DICT_4X4_50", legacy_pattern=True
)  # even rows: layouts differ


def _render(board: BoardSpec, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    T = place_board(CAMERA, board, tilt_rotation(math.radians(20), 1.0, 0.2), (320.0, 240.0), 0.45)
    return render_view(CAMERA, board, T, np.random.default_rng(seed)), true_corners_px(CAMERA, board, T)


@pytest.fixture(scope="module")
def inverted_view() -> tuple[np.ndarray, np.ndarray]:
    return _render(INVERTED)


@pytest.fixture(scope="module")
def legacy_view() -> tuple[np.ndarray, np.ndarray]:
    return _render(LEGACY)


def test_an_inverted_board_is_found_only_when_declared_inverted(inverted_view) -> None:
    gray, truth = inverted_view
    det, why = detect_board(gray, INVERTED)
    assert det is not None, why
    assert len(det.corner_ids) == INVERTED.n_corners
    assert np.linalg.norm(det.corners_px - truth[det.corner_ids], axis=1).mean() < 0.1
    det, why = detect_board(gray, replace(INVERTED, inverted=False))
    assert det is None and "0 markers" in why


def test_an_undeclared_inversion_is_named_with_what_was_seen(inverted_view) -> None:
    plain = replace(INVERTED, inverted=False)
    counts = charuco_variant_counts([inverted_view[0]], plain)
    assert counts.markers_normal == 0 and counts.markers_inverted > 0
    advice = charuco_variant_advice(counts, plain)
    assert advice is not None and advice.endswith("declare --inverted (white markers on black)")
    assert "0 markers with DICT_4X4_1000 normal" in advice
    assert charuco_variant_advice(charuco_variant_counts([inverted_view[0]], INVERTED), INVERTED) is None


def test_a_legacy_board_needs_its_layout_declared(legacy_view) -> None:
    gray, truth = legacy_view
    det, why = detect_board(gray, LEGACY)
    assert det is not None, why
    assert np.linalg.norm(det.corners_px - truth[det.corner_ids], axis=1).mean() < 0.1
    current = replace(LEGACY, legacy_pattern=False)
    det, _ = detect_board(gray, current)
    assert det is None or len(det.corner_ids) < LEGACY.n_corners // 2
    advice = charuco_variant_advice(charuco_variant_counts([gray], current), current)
    assert advice is not None and advice.endswith("declare --legacy (OpenCV < 4.6 layout)")


def test_a_wrong_dictionary_is_named_with_the_one_that_reads_the_markers(legacy_view) -> None:
    wrong = replace(LEGACY, dictionary="DICT_6X6_50")
    counts = charuco_variant_counts([legacy_view[0]], wrong)
    assert counts.markers_inverted == 0
    advice = charuco_variant_advice(counts, wrong)
    assert advice is not None and advice.endswith("declare --dictionary DICT_4X4_1000")


def test_variants_apply_to_charuco_only() -> None:
    with pytest.raises(ValueError, match="ChArUco boards only"):
        BoardSpec("chessboard", 9, 6, 0.025, inverted=True)
