"""Kalibr's AprilGrid: the point layout and ids as Kalibr numbers them, the print as Kalibr draws it, and
detection through cv2.aruco's AprilTag dictionary onto those ids."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibctl.core.board.board_geometry import aprilgrid_tag_point_ids
from calibctl.core.board.board_spec import APRILGRID_BORDER_BITS, BoardSpec
from calibctl.core.capture.detect import detect_board
from calibctl.core.synth.pinhole import (
    APRILGRID_TEXTURE_PX_PER_TAG,
    Photometry,
    PinholeCamera,
    aprilgrid_texture,
    render_view,
    true_corners_px,
)
from calibctl.core.synth.scenes import place_board, tilt_rotation

CAMERA = PinholeCamera.seed_reference()
GRID = BoardSpec.aprilgrid(4, 3, 0.04, 0.3)  # 4 tag columns, 3 tag rows
KALIBR_TAG0_36H11 = 0xD5D628584  # kalibr_create_target_pdf's t36h11[0]


@pytest.fixture(scope="module")
def grid_view() -> tuple[np.ndarray, np.ndarray]:
    T = place_board(CAMERA, GRID, tilt_rotation(math.radians(25), 0.7, 0.15), (320.0, 240.0), 0.5)
    return render_view(CAMERA, GRID, T, np.random.default_rng(4)), true_corners_px(CAMERA, GRID, T)


def test_points_follow_kalibrs_layout() -> None:
    size, gap = 0.04, 0.3 * 0.04
    points = GRID.object_points()
    assert points.shape == (8 * 6, 3) and GRID.n_corners == 48
    # row 0: tag 0's bottom edge, then tag 1's (one gap further), y = 0
    np.testing.assert_allclose(points[:4, :2], [[0, 0], [size, 0], [size + gap, 0], [2 * size + gap, 0]])
    # row 1 (point 8) is tag 0's top-left corner; row 2 starts tag 4's bottom-left, one pitch up
    np.testing.assert_allclose(points[8, :2], [0, size])
    np.testing.assert_allclose(points[16, :2], [0, size + gap])
    # tag 5 (column 1, row 1): bottom-left, bottom-right, top-right, top-left
    ids = aprilgrid_tag_point_ids(np.array([5]), GRID.cols)[0]
    x0 = y0 = size + gap
    np.testing.assert_allclose(
        points[ids, :2], [[x0, y0], [x0 + size, y0], [x0 + size, y0 + size], [x0, y0 + size]]
    )


def test_the_print_draws_tag_bits_as_kalibr_does() -> None:
    """Kalibr: bit 6i + j of the code clear = black cell (i, j); turned 180 degrees; row 0 printed on top."""
    cells = np.zeros((6, 6), bool)
    for i in range(6):
        for j in range(6):
            cells[i, j] = not KALIBR_TAG0_36H11 & (1 << (6 * i + j))
    black_printed = np.rot90(cells, 2)  # as seen on the sheet, top row first
    texture = aprilgrid_texture(GRID)
    pps = APRILGRID_TEXTURE_PX_PER_TAG
    gap = round(GRID.tag_spacing * pps)
    bit = pps // (6 + 2 * APRILGRID_BORDER_BITS)
    tag0 = texture[gap : gap + pps, gap : gap + pps][::-1]  # texture rows grow with y: flip to top-first
    centres = (np.arange(6) + APRILGRID_BORDER_BITS) * bit + bit // 2
    printed_black = tag0[np.ix_(centres, centres)] < 128
    np.testing.assert_array_equal(printed_black, black_printed)
    assert np.all(tag0[: 2 * bit - 1, :] < 128)  # the two-bit black border
    assert np.all(texture[:gap, :gap] < 128) and np.all(texture[:gap, gap + 2 : gap + pps - 2] > 128)


def test_detection_gives_kalibrs_ids(grid_view) -> None:
    gray, truth = grid_view
    detection, why = detect_board(gray, GRID)
    assert detection is not None, why
    assert detection.method == "aprilgrid" and len(detection.corner_ids) >= 40
    errors = np.linalg.norm(detection.corners_px - truth[detection.corner_ids], axis=1)
    assert errors.max() < 0.3


def test_a_partly_hidden_grid_keeps_its_ids(grid_view) -> None:
    gray, truth = grid_view
    hidden = gray.copy()
    left_of = int(truth[:, 0].min() + 0.5 * np.ptp(truth[:, 0]))
    hidden[:, left_of:] = 128
    detection, why = detect_board(hidden, GRID)
    assert detection is not None, why
    assert 8 <= len(detection.corner_ids) < GRID.n_corners
    errors = np.linalg.norm(detection.corners_px - truth[detection.corner_ids], axis=1)
    assert errors.max() < 0.3


def test_a_dim_grid_is_found_too() -> None:
    """The threshold follows the image's contrast: a fixed one fit for a bright print loses a dim one."""
    T = place_board(CAMERA, GRID, tilt_rotation(math.radians(20), 2.0, 0.1), (320.0, 240.0), 0.5)
    gray = render_view(CAMERA, GRID, T, np.random.default_rng(5), Photometry(gain=40.0))
    assert np.percentile(gray, 95) - np.percentile(gray, 5) < 60
    detection, why = detect_board(gray, GRID)
    assert detection is not None and len(detection.corner_ids) >= 40, why
    errors = np.linalg.norm(
        detection.corners_px - true_corners_px(CAMERA, GRID, T)[detection.corner_ids], axis=1
    )
    assert errors.max() < 0.4


def test_an_image_without_the_grid_says_what_it_read() -> None:
    detection, why = detect_board(np.full((240, 320), 200, np.uint8), GRID)
    assert detection is None and "0 of its 12 DICT_APRILTAG_36h11 tags" in why


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tag_spacing": 0.0}, "tag spacing"),
        ({"tag_spacing": 1.5}, "tag spacing"),
        ({"family": "25h7"}, "OpenCV has no AprilTag family '25h7'"),
    ],
)
def test_bad_grids_are_refused(kwargs, message) -> None:
    args = {"tag_cols": 4, "tag_rows": 3, "tag_size_m": 0.04, "tag_spacing": 0.3, **kwargs}
    with pytest.raises(ValueError, match=message):
        BoardSpec.aprilgrid(**args)


def test_an_odd_corner_grid_is_not_an_aprilgrid() -> None:
    with pytest.raises(ValueError, match="two corners per tag"):
        BoardSpec("aprilgrid", 7, 6, 0.04, dictionary="DICT_APRILTAG_36h11", tag_spacing=0.3)
