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
    assert results[1][1] == (
        "no 7x10 chessboard: nothing chessboard-like at a quick look (a full search runs on "
        "every 5th frame and after each board)"
    )
    assert results[0][1].startswith("no 7x10 chessboard found")


@needs_datasets
def test_a_board_the_quick_check_misses_is_found_within_five_frames_and_then_kept() -> None:
    """baka-stereo left_001772846857023.jpg: checkChessboard says no (on the 640 px copy), the classic
    detector finds the board. Held in view from frame 3 on, it is found at frame 6 and in every frame
    after."""
    board = cv2.imread(str(BAKA_STEREO / "left" / "left_001772846857023.jpg"), cv2.IMREAD_GRAYSCALE)
    small = cv2.resize(
        board,
        (
            board.shape[1] * STREAM_CHECK_SIDE_PX // board.shape[1],
            board.shape[0] * STREAM_CHECK_SIDE_PX // board.shape[1],
        ),
        interpolation=cv2.INTER_AREA,
    )
    assert not cv2.checkChessboard(small, (7, 10))
    blank = np.full_like(board, 128)
    detector = StreamDetector(BAKA_BOARD, full_every=5)
    found = [detector.detect(frame)[0] is not None for frame in [blank, blank] + [board] * 8]
    assert found == [False] * 5 + [True] * 5


def _ahead(detector: StreamDetector, frames: list[np.ndarray]) -> list[tuple[object, str]]:
    """The frames as a capture with jobs > 1 detects them: every frame probed first (as if on other workers,
    knowing only whether it is forced), then settled in order."""
    planned = [(gray, detector.next_forced()) for gray in frames]
    probes = [
        frame_select.probe_frame(gray, detector.spec, detector.settings, forced) for gray, forced in planned
    ]
    return [
        detector.settle(gray, forced, probe) for (gray, forced), probe in zip(planned, probes, strict=True)
    ]


def _same(a: list[tuple[object, str]], b: list[tuple[object, str]]) -> bool:
    def key(found):
        det, why = found
        return why, None if det is None else (det.corner_ids.tolist(), det.corners_px.tobytes())

    return [key(x) for x in a] == [key(x) for x in b]


def test_frames_probed_ahead_get_the_one_thread_detections(tmp_path_factory) -> None:
    """A board then blank frames: the blank frame after the board is due for the full search, which a probe
    run ahead cannot know; settle runs it, so the answers (why included) equal the one-thread detector's."""
    from tests.workflows.synth_folders import rendered

    folder = rendered(tmp_path_factory, "good")
    board = cv2.imread(str(sorted(folder.glob("*.png"))[0]), cv2.IMREAD_GRAYSCALE)
    blank = np.full_like(board, 128)
    spec = BoardSpec.chessboard(9, 6, 0.025)
    frames = [blank, board, board, blank, blank, blank, blank, board, blank, blank, blank, blank, blank]
    one_thread = StreamDetector(spec, full_every=5)
    expected = [one_thread.detect(gray) for gray in frames]
    ahead = StreamDetector(spec, full_every=5)
    got = _ahead(ahead, frames)
    assert _same(got, expected)
    assert [det is not None for det, _ in got] == [gray is board for gray in frames]
    assert ahead.settled_searches == 2  # the blank frame right after each board
    assert one_thread.settled_searches == 0


@needs_datasets
def test_a_board_the_quick_check_misses_is_settled_as_the_one_thread_detector_finds_it() -> None:
    board = cv2.imread(str(BAKA_STEREO / "left" / "left_001772846857023.jpg"), cv2.IMREAD_GRAYSCALE)
    blank = np.full_like(board, 128)
    frames = [blank, blank] + [board] * 8 + [blank] * 2
    one_thread = StreamDetector(BAKA_BOARD, full_every=5)
    expected = [one_thread.detect(gray) for gray in frames]
    ahead = StreamDetector(BAKA_BOARD, full_every=5)
    assert _same(_ahead(ahead, frames), expected)
    assert (
        ahead.settled_searches == 4
    )  # frames 7-10: the quick check misses the board the frame before showed
