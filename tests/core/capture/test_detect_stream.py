"""StreamDetector: the quick check only postpones the full search on a stream, it never loses a board."""

from __future__ import annotations

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import frame_select
from calibctl.core.capture.frame_select import STREAM_CHECK_SIDE_PX, StreamDetector
from tests.datasets import BAKA_STEREO, needs_datasets

BAKA_BOARD = BoardSpec.chessboard(7, 10, 0.023)


def test_board_free_frames_get_the_full_search_only_every_fifth_frame(monkeypatch) -> None:
    calls: list[int] = []
    real = frame_select.detect_board

    def counted(gray, spec, settings=None):
        calls.append(int(gray[0, 0]))
        return real(gray, spec, settings)

    monkeypatch.setattr(frame_select, "detect_board", counted)
    detector = StreamDetector(BAKA_BOARD, full_every=5)
    results = [detector.detect(np.full((720, 1280), i, np.uint8)) for i in range(12)]
    assert calls == [0, 5, 10]  # frames 1, 6 and 11
    assert all(det is None for det, _ in results)
    assert results[1][1] == ("no 7x10 chessboard: nothing chessboard-like at a quick look (a full search runs on "
                             "every 5th frame and after each board)")
    assert results[0][1].startswith("no 7x10 chessboard found")


@needs_datasets
def test_a_board_the_quick_check_misses_is_found_within_five_frames_and_then_kept() -> None:
    """baka-stereo left_001772846857023.jpg: checkChessboard says no (on the 640 px copy), the classic
    detector finds the board. Held in view from frame 3 on, it is found at frame 6 and in every frame after."""
    board = cv2.imread(str(BAKA_STEREO / "left" / "left_001772846857023.jpg"), cv2.IMREAD_GRAYSCALE)
    small = cv2.resize(board, (board.shape[1] * STREAM_CHECK_SIDE_PX // board.shape[1],
                               board.shape[0] * STREAM_CHECK_SIDE_PX // board.shape[1]), interpolation=cv2.INTER_AREA)
    assert not cv2.checkChessboard(small, (7, 10))
    blank = np.full_like(board, 128)
    detector = StreamDetector(BAKA_BOARD, full_every=5)
    found = [detector.detect(frame)[0] is not None for frame in [blank, blank] + [board] * 8]
    assert found == [False] * 5 + [True] * 5
