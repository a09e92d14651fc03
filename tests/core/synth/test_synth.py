"""The ray-casting renderer and the scenario poses: does the picture agree with the truth it claims?"""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.intrinsics.fisheye_model import project_equidistant
from calibctl.core.synth.fisheye import FisheyeCamera
from calibctl.core.synth.pinhole import (
    Photometry,
    PinholeCamera,
    distort_normalised,
    render_view,
    true_corners_px,
    undistort_normalised,
)
from calibctl.core.synth.scenes import (
    fits_in_frame,
    place_board,
    scenario_poses,
    tilt_rotation,
    video_plan,
)

BOARD = BoardSpec.chessboard(9, 6, 0.025)
CAMERA = PinholeCamera.seed_reference()
INVERSE_TOL = 1e-10  # normalised units (~1e-7 px)
EDGE_TOL_PX = 0.02  # 36 sub-samples resolve an axis-aligned edge to 1/72 px, plus 8-bit rounding
CLEAN = Photometry(blur_sigma_px=0.0, read_noise_dn=0.0, shot_noise_gain=0.0)


def tilt_deg(T: np.ndarray) -> float:
    return math.degrees(math.acos(abs(T[2, 2])))


def far_side_deg(T: np.ndarray) -> float:
    n = T[:3, 2]
    m = -n if n[2] > 0 else n
    return math.degrees(math.atan2(m[1], m[0])) % 360.0


def test_inverse_distortion_round_trips_over_the_whole_image() -> None:
    u, v = np.meshgrid(np.linspace(0, 639, 41), np.linspace(0, 479, 31))
    xd, yd = (u - CAMERA.K[0, 2]) / 800.0, (v - CAMERA.K[1, 2]) / 800.0
    x, y = undistort_normalised(xd, yd, CAMERA.dist)
    xr, yr = distort_normalised(x, y, CAMERA.dist)
    assert np.max(np.abs(xr - xd)) < INVERSE_TOL and np.max(np.abs(yr - yd)) < INVERSE_TOL
    # and the corner of the image really is pulled inward (barrel, k1 = -0.28): the ray is wider
    assert abs(x[0, 0]) > abs(xd[0, 0])


def test_seed_lens_scales_with_readout_resolution() -> None:
    big = PinholeCamera.seed_reference((1280, 960))
    assert big.K[0, 0] == pytest.approx(1600.0) and big.K[0, 2] == pytest.approx(639.5)
    np.testing.assert_array_equal(big.dist, CAMERA.dist)


def square_centre_px(T: np.ndarray, col: float, row: float) -> tuple[int, int]:
    point = np.array([[col * BOARD.square_size_m, row * BOARD.square_size_m, 0.0]])
    u, v = CAMERA.project(point, T)[0]
    return int(round(u)), int(round(v))


def test_rendered_pattern_is_where_the_truth_says() -> None:
    T = place_board(CAMERA, BOARD, tilt_rotation(math.radians(30), 0.8, 0.3), (330.0, 250.0), 0.55)
    img = render_view(CAMERA, BOARD, T, np.random.default_rng(0), CLEAN, np.full((480, 640), 0.4))
    # square (i, j) spans corners (i..i+1, j..j+1); (-1, -1) is the black square outside corner 0
    for i in range(-1, BOARD.cols):
        for j in range(-1, BOARD.rows):
            u, v = square_centre_px(T, i + 0.5, j + 0.5)
            black = (i + j) % 2 == 0
            assert (img[v, u] < 60) == black, (i, j, img[v, u])
    # the quiet zone is white and the background mid-grey
    u, v = square_centre_px(T, -1.5, 2.0)
    assert img[v, u] > 150
    assert 80 < img[5, 5] < 120


def test_rendering_is_deterministic_per_seed() -> None:
    T = scenario_poses("good", CAMERA, BOARD, 1, np.random.default_rng(3))[0]
    a = render_view(CAMERA, BOARD, T, np.random.default_rng(5))
    b = render_view(CAMERA, BOARD, T, np.random.default_rng(5))
    c = render_view(CAMERA, BOARD, T, np.random.default_rng(6))
    np.testing.assert_array_equal(a, b)
    assert a.dtype == np.uint8 and a.shape == (480, 640)
    assert np.any(a != c)


def test_anti_aliasing_places_edges_to_a_fiftieth_of_a_pixel() -> None:
    """Shift a square-on board by fractions of a pixel; the black-to-white edge between squares (0, 0)
    and (1, 0), measured by area (sum of the white fraction across it), must follow the truth."""
    pinhole = PinholeCamera(CAMERA.K, np.zeros(5), CAMERA.image_size)
    for shift_px in (0.0, 0.125, 0.3, 0.5):
        T = place_board(pinhole, BOARD, np.eye(3), (319.5 + shift_px, 239.5), 0.6)
        img = render_view(pinhole, BOARD, T, np.random.default_rng(0), CLEAN, np.full((480, 640), 0.4))
        edge_u, _ = pinhole.project(np.array([[BOARD.square_size_m, 0.0, 0.0]]), T)[0]
        _, row_v = pinhole.project(
            np.array([[0.5 * BOARD.square_size_m, 0.5 * BOARD.square_size_m, 0.0]]), T
        )[0]
        lo, hi = int(edge_u) - 6, int(edge_u) + 6
        profile = img[int(round(row_v)), lo : hi + 1].astype(float)
        black, white = 0.06 * CLEAN.gain, 0.90 * CLEAN.gain
        white_fraction = np.clip((profile - black) / (white - black), 0.0, 1.0)
        measured = hi + 0.5 - white_fraction.sum()
        assert measured == pytest.approx(edge_u, abs=EDGE_TOL_PX), shift_px


def test_true_corners_are_the_projected_model() -> None:
    T = scenario_poses("good", CAMERA, BOARD, 1, np.random.default_rng(1))[0]
    corners = true_corners_px(CAMERA, BOARD, T)
    assert corners.shape == (54, 2)
    grid = corners.reshape(6, 9, 2)
    # row-major ids: x grows along a row, y along a column, for a board that is not spun much
    assert np.all(np.diff(grid[..., 0], axis=1) > 0) and np.all(np.diff(grid[..., 1], axis=0) > 0)


@pytest.mark.parametrize("size", [(640, 480), (1280, 720)])
def test_good_scenario_tilts_in_every_direction_and_stays_in_frame(size: tuple[int, int]) -> None:
    camera = PinholeCamera.seed_reference(size)
    poses = scenario_poses("good", camera, BOARD, 12, np.random.default_rng(2))
    assert all(fits_in_frame(camera, BOARD, T) for T in poses)
    assert all(20.0 <= tilt_deg(T) <= 40.0 for T in poses)
    bins = {round(far_side_deg(T) / 45.0) % 8 for T in poses}
    assert len(bins) >= 4


def test_failure_scenarios_do_what_their_names_say() -> None:
    rng = np.random.default_rng(4)
    flat = scenario_poses("flat", CAMERA, BOARD, 12, rng)
    assert all(tilt_deg(T) < 5.0 for T in flat)
    one = scenario_poses("one-direction", CAMERA, BOARD, 12, rng)
    assert all(min(far_side_deg(T), 360 - far_side_deg(T)) < 15.0 for T in one)
    centre = scenario_poses("centre", CAMERA, BOARD, 12, rng)
    for T in centre:
        px = true_corners_px(CAMERA, BOARD, T)
        assert np.all((px[:, 0] > 640 / 3) & (px[:, 0] < 1280 / 3) & (px[:, 1] > 160) & (px[:, 1] < 320))


def test_video_plan_pauses_at_key_poses_and_moves_between() -> None:
    plan = video_plan(CAMERA, BOARD, 3, np.random.default_rng(0), still_frames=4, move_frames=5)
    assert len(plan.poses) == 3 * 4 + 2 * 5
    assert plan.still == ([True] * 4 + [False] * 5) * 2 + [True] * 4
    corners = [true_corners_px(CAMERA, BOARD, T) for T in plan.poses]
    motion = [float(np.linalg.norm(b - a, axis=1).mean()) for a, b in zip(corners, corners[1:], strict=False)]
    still_steps = [m for m, s0, s1 in zip(motion, plan.still, plan.still[1:], strict=False) if s0 and s1]
    moving_steps = [
        m for m, s0, s1 in zip(motion, plan.still, plan.still[1:], strict=False) if not (s0 and s1)
    ]
    assert max(still_steps) < 0.2 and min(moving_steps) > 2.0


def test_scenarios_refuse_unknown_names_and_impossible_frames() -> None:
    with pytest.raises(ValueError, match="unknown still scenario"):
        scenario_poses("sideways", CAMERA, BOARD, 3, np.random.default_rng(0))
    huge = BoardSpec.chessboard(40, 30, 0.1)
    with pytest.raises(ValueError, match="cannot place the board"):
        scenario_poses("good", CAMERA, huge, 1, np.random.default_rng(0))


def test_a_190_deg_fisheye_renders_the_board_behind_the_camera_plane() -> None:
    # A wall-like board 0.1 m to the right, reaching behind the camera plane (Z < 0): the ray 93 deg
    # off-axis towards +X hits it at Z = -5 mm, 3.79 x 1.5 squares from corner 0, inside a black square.
    camera = FisheyeCamera.from_fov((640, 480), 190.0)
    board = BoardSpec.chessboard(9, 6, 0.025)
    T_cam_board = np.eye(4)
    T_cam_board[:3, :3] = np.column_stack([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    T_cam_board[:3, 3] = [0.1, -0.0375, -0.1]
    background = np.full((480, 640), 0.4, np.float32)  # 94 DN at gain 235
    img = render_view(
        camera,
        board,
        T_cam_board,
        np.random.default_rng(0),
        Photometry(blur_sigma_px=0.0, read_noise_dn=0.0, shot_noise_gain=0.0),
        background,
    )
    ray = np.array([[np.sin(np.deg2rad(93.0)), 0.0, np.cos(np.deg2rad(93.0))]])
    u, v = np.rint(project_equidistant(ray, camera.K, camera.dist)[0]).astype(int)
    assert (
        camera.circle_radius_px is not None
        and np.hypot(u - camera.K[0, 2], v - camera.K[1, 2]) < camera.circle_radius_px
    )
    assert img[v, u] < 30  # black print (235 x 0.06 x 0.8 = 11 DN), not the background
