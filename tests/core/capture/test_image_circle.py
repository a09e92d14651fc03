"""core.capture.image_circle: the circle found in a session's frames (or not), the cells it covers, and the
gates and the fold-over check read through it."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture.detect import detect_board
from calibctl.core.capture.gates import evaluate_gates
from calibctl.core.capture.image_circle import (
    ImageCircle,
    accumulate_max,
    cells_inside,
    circle_detail,
    circle_from_detail,
    circle_problem,
    detect_image_circle,
)
from calibctl.core.intrinsics.lens_checks import check_distortion_foldover, check_equidistant_foldover
from calibctl.workflows.synth.synth import run_synth
from tests.datasets import LEFT_RIGHT, needs_datasets

SIZE = (640, 480)
CENTRE_TOLERANCE_PX = 1.5  # the half-size maximum picture locates the circle to about a pixel
CORNER_CELLS = {(0, 0), (0, 2), (2, 0), (2, 2)}
SPEC = BoardSpec.chessboard(9, 6, 0.025)


def _max_picture(paths: list[Path]) -> np.ndarray:
    acc = None
    for path in paths:
        acc = accumulate_max(acc, cv2.imread(str(path), cv2.IMREAD_REDUCED_GRAYSCALE_2))
    assert acc is not None
    return acc


@pytest.fixture(scope="module")
def circular_190(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 190 deg circular fisheye session at 640x480, seed 6: its corners miss the top-left cell (on OpenCV
    4.10
    and 5.0 alike: seed 4 lost a rim view and a tilt direction to 4.10's detector)."""
    out = tmp_path_factory.mktemp("fisheye") / "r190"
    run_synth(out, "good", seed=6, views=12, image_size=SIZE, fisheye_fov_deg=190.0)
    return out


def _views(folder: Path) -> list[BoardView]:
    views = []
    for path in sorted(folder.glob("view-*.png")):
        det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), SPEC)
        if det is not None:
            views.append(BoardView(path.name, det.corner_ids, det.corners_px))
    return views


def test_the_circle_of_a_circular_fisheye_is_found_where_the_render_put_it(circular_190: Path) -> None:
    truth = json.loads((circular_190 / "truth.json").read_text())["camera"]
    circle = detect_image_circle(_max_picture(sorted(circular_190.glob("view-*.png"))), SIZE)
    assert circle is not None and circle.source == "detected"
    K = np.array(truth["K"])
    assert (
        abs(circle.cx_px - K[0, 2]) < CENTRE_TOLERANCE_PX
        and abs(circle.cy_px - K[1, 2]) < CENTRE_TOLERANCE_PX
    )
    assert abs(circle.radius_px - truth["image_circle_px"]) < CENTRE_TOLERANCE_PX


def test_a_pinhole_render_and_real_pinhole_photos_have_no_circle(tmp_path: Path) -> None:
    run_synth(tmp_path / "good", "good", seed=1, views=4, image_size=SIZE)
    assert detect_image_circle(_max_picture(sorted((tmp_path / "good").glob("*.png"))), SIZE) is None


@needs_datasets
def test_real_pinhole_photos_have_no_circle() -> None:
    assert detect_image_circle(_max_picture(sorted(LEFT_RIGHT.glob("left*.jpg"))), SIZE) is None


def test_a_dark_picture_a_lit_frame_and_a_dark_vignette_are_not_circles() -> None:
    h, w = 240, 320
    assert detect_image_circle(np.full((h, w), 8, np.uint8), SIZE) is None  # never lit
    assert detect_image_circle(np.full((h, w), 200, np.uint8), SIZE) is None  # corners lit: pinhole
    vignette = np.zeros((h, w), np.uint8)
    vignette[20:-20, 20:-20] = 180  # dark corners, but a rectangle, not a disc
    assert detect_image_circle(vignette, SIZE) is None


def test_a_circle_is_found_when_dark_things_inside_it_reach_its_rim() -> None:
    """The lens housing or a dark scene inside the circle bounds the lit region along part of the rim (a
    real 960x600 circular fisheye had no circle for it and was asked to cover its black corners); the
    rim that is left still gives the circle, and a rectangle with a dark notch is still no circle."""
    h, w = 240, 320
    v, u = np.mgrid[0:h, 0:w]
    cx, cy, r = 161.0, 118.0, 110.0
    picture = np.where(np.hypot(u - cx, v - cy) <= r, 200, 6).astype(np.uint8)
    d = np.hypot(u - cx, v - cy)
    picture[(v > cy + 0.3 * r) & (d > 0.6 * r) & (d < r - 4)] = 6  # the housing: dark inside a lit crescent
    picture[np.hypot(u - (cx - r), v - cy) < 30] = 6  # a dark object that reaches the rim at the left
    circle = detect_image_circle(picture, (2 * w, 2 * h))
    assert circle is not None
    # full-resolution pixels: the picture is at half size
    assert abs(circle.cx_px - (2 * cx + 0.5)) < 2 * CENTRE_TOLERANCE_PX
    assert abs(circle.cy_px - (2 * cy + 0.5)) < 2 * CENTRE_TOLERANCE_PX
    assert abs(circle.radius_px - 2 * r) < 2 * CENTRE_TOLERANCE_PX
    notched = np.full((h, w), 6, np.uint8)
    notched[20:-20, 20:-20] = 180
    notched[100:140, 20:120] = 6  # concave, but what is left of its boundary is straight, not a circle
    assert detect_image_circle(notched, SIZE) is None


def test_only_cells_mostly_inside_the_circle_are_asked_for() -> None:
    circle = ImageCircle(322.8, 237.4, 236.0, "given")
    assert cells_inside(circle, SIZE, 3) == {(r, c) for r in range(3) for c in range(3)} - CORNER_CELLS
    assert cells_inside(ImageCircle(320, 240, 2000, "given"), SIZE, 3) == {
        (r, c) for r in range(3) for c in range(3)
    }


@pytest.mark.parametrize(
    ("circle", "words"),
    [
        ((700.0, 200.0, 100.0), "centre (700, 200) px lies outside the 640x480 image"),
        ((320.0, 240.0, 0.0), "radius must be positive, got 0 px"),
        ((320.0, 240.0, 10.0), "covers no cell of the 3x3 coverage grid"),
        ((320.0, float("nan"), 10.0), "is not three finite numbers"),
    ],
)
def test_a_circle_that_cannot_be_the_image_circle_is_named_with_its_numbers(circle, words) -> None:
    problem = circle_problem(circle, SIZE)
    assert problem is not None and words in problem
    assert circle_problem((322.8, 237.4, 236.0), SIZE) is None


def test_a_circular_session_passes_coverage_with_its_circle_and_fails_without_it(circular_190: Path) -> None:
    views = _views(circular_190)
    circle = detect_image_circle(_max_picture(sorted(circular_190.glob("view-*.png"))), SIZE)
    assert circle is not None
    without = evaluate_gates(views, SPEC.object_points(), SIZE).gate("coverage")
    # which black corner the detected corners miss depends on the OpenCV version's detector; a corner it is
    corner_names = {"top-left corner", "top-right corner", "bottom-left corner", "bottom-right corner"}
    assert not without.passed and set(without.detail["missing_cells"]) <= corner_names  # type: ignore[arg-type]
    with_circle = evaluate_gates(views, SPEC.object_points(), SIZE, image_circle=circle).gate("coverage")
    assert with_circle.passed and (with_circle.value, with_circle.threshold) == (5.0, 5.0)
    assert sorted(with_circle.detail["cells_outside_circle"]) == sorted(  # type: ignore[arg-type]
        ["top-left corner", "top-right corner", "bottom-left corner", "bottom-right corner"]
    )
    assert circle_from_detail(with_circle.detail) == ImageCircle(
        *(round(x, 2) for x in circle.as_tuple()), source="detected"
    )
    # a cell inside the circle that no corner reaches is still asked for, by name
    left_only = [v for v in views if np.asarray(v.corners_px)[:, 0].max() < 2 * SIZE[0] / 3]
    missed = evaluate_gates(left_only, SPEC.object_points(), SIZE, image_circle=circle).gate("coverage")
    assert not missed.passed and "right edge" in missed.detail["missing_cells"]  # type: ignore[operator]
    assert (
        missed.hint is not None and "right edge" in missed.hint and "inside the image circle" in missed.hint
    )
    assert "corner" not in " ".join(missed.detail["missing_cells"])  # type: ignore[arg-type]


def test_an_older_detail_without_a_circle_reads_as_none() -> None:
    assert circle_from_detail({"missing_cells": []}) is None
    circle = ImageCircle(1.0, 2.0, 3.0, "given")
    assert circle_from_detail(circle_detail(circle)) == circle


def test_foldover_beyond_the_image_circle_is_not_held_against_a_pinhole_model() -> None:
    # r_d = r (1 - 0.2 r^2) peaks at r_d = 0.861: short of the image corner (400 / 300 = 1.33), past the
    # circle (236 / 300 = 0.79)
    K = np.array([[300.0, 0.0, 319.5], [0.0, 300.0, 239.5], [0.0, 0.0, 1.0]])
    dist = np.array([-0.2, 0.0, 0.0, 0.0, 0.0])
    assert not check_distortion_foldover(K, dist, SIZE).passed
    inside = check_distortion_foldover(K, dist, SIZE, (319.5, 239.5, 236.0))
    assert inside.passed and "inside the image circle" in inside.message
    assert not check_distortion_foldover(
        K, dist, SIZE, (319.5, 239.5, 280.0)
    ).passed  # r_d 0.93: folds inside


def test_the_equidistant_foldover_stops_at_the_circle() -> None:
    # theta_d = theta (1 - 0.06 theta^2) peaks at theta = 2.36 rad (135 deg), theta_d = 1.57
    K = np.array([[140.0, 0.0, 319.5], [0.0, 140.0, 239.5], [0.0, 0.0, 1.0]])
    dist = np.array([-0.06, 0.0, 0.0, 0.0])
    assert check_equidistant_foldover(
        K, dist, SIZE, (319.5, 239.5, 200.0)
    ).passed  # theta_d 1.43 at the circle
    folded = check_equidistant_foldover(K, dist, SIZE, (319.5, 239.5, 236.0))  # theta_d 1.69: past the peak
    assert not folded.passed and "inside the image circle" in folded.message
