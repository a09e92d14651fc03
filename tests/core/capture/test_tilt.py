"""Tilt readout against known truth, views too sparse to read, and directions that are really distinct."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture.gates import GateThresholds, evaluate_gates
from calibctl.core.capture.tilt import MIN_TILT_CORNERS, directions_to_add, distinct_directions
from calibctl.core.synth.pinhole import PinholeCamera, true_corners_px
from calibctl.core.synth.scenes import place_board, sweep_poses, tilt_rotation

BOARD = BoardSpec.chessboard(9, 6, 0.025)
NOISE_PX = 0.1
# the bar for per-view tilt against truth
TILT_SD_MAX_DEG = 2.0
TILT_ERR_MAX_DEG = 5.0


def projected_session(camera: PinholeCamera, seed: int, n_views: int = 20, tilt_deg=(0.0, 50.0)):
    rng = np.random.default_rng(seed)
    poses, truth = sweep_poses(camera, BOARD, n_views, rng, tilt_deg)
    views = [
        BoardView(
            f"v{i}",
            np.arange(BOARD.n_corners),
            true_corners_px(camera, BOARD, T) + rng.normal(0.0, NOISE_PX, (BOARD.n_corners, 2)),
        )
        for i, T in enumerate(poses)
    ]
    return views, np.array(truth)


def tilt_errors(camera: PinholeCamera, seeds, tilt_deg=(0.0, 50.0)) -> tuple[np.ndarray, np.ndarray]:
    errors, truths = [], []
    for seed in seeds:
        views, truth = projected_session(camera, seed, tilt_deg=tilt_deg)
        report = evaluate_gates(views, BOARD.object_points(), camera.image_size)
        assert len(report.views) == len(views) and report.unused_views == ()
        errors.append(np.array([g.tilt_deg for g in report.views]) - truth)
        truths.append(truth)
    return np.concatenate(errors), np.concatenate(truths)


@pytest.mark.parametrize("size", [(1280, 960), (640, 480)])
def test_tilt_reads_true_through_the_seed_lens_across_0_to_50_degrees(size) -> None:
    # seed lens k1 = -0.28: the old homography readout was off by up to 10 deg here (BENCHMARKS.md)
    errors, truth = tilt_errors(PinholeCamera.seed_reference(size), seeds=range(5))
    assert truth.min() < 5.0 and truth.max() > 45.0  # the sweep covers near-flat and steep views
    assert errors.std() < TILT_SD_MAX_DEG
    assert np.abs(errors).max() < TILT_ERR_MAX_DEG


def test_near_flat_views_read_near_flat_even_at_the_image_edge() -> None:
    errors, truth = tilt_errors(
        PinholeCamera.seed_reference((1280, 960)), seeds=range(3), tilt_deg=(0.0, 4.0)
    )
    assert np.all(truth + errors < 4.0 + TILT_ERR_MAX_DEG)
    assert np.abs(errors).max() < TILT_ERR_MAX_DEG


def test_a_flat_session_with_another_focal_length_still_reads_flat() -> None:
    # too flat to fit f: it is held at the image diagonal (2x the true f here); a flat board's tilt is f-free
    K = np.array([[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]])
    camera = PinholeCamera(K, np.array([-0.1, 0.01, 0.0, 0.0, 0.0]), (640, 480))
    views, truth = projected_session(camera, 3, tilt_deg=(0.0, 3.0))
    report = evaluate_gates(views, BOARD.object_points(), camera.image_size)
    assert report.focal_source == "nominal"
    assert max(g.tilt_deg for g in report.views) < 3.0 + TILT_ERR_MAX_DEG
    assert not report.gate("tilt").passed and not report.gate("observability").passed


def sparse_session(extra: list[BoardView]) -> list[BoardView]:
    camera = PinholeCamera.seed_reference((640, 480))
    views, _ = projected_session(camera, 11, n_views=12, tilt_deg=(20.0, 40.0))
    return views + extra


def test_a_view_with_too_few_corners_is_not_used_and_the_report_says_why() -> None:
    camera = PinholeCamera.seed_reference((640, 480))
    T = place_board(camera, BOARD, tilt_rotation(math.radians(10.0), 0.0, 0.0), (320.0, 240.0), 0.5)
    ids = np.array([0, 1, 2, 9, 10, 11])  # a 6-corner partial view (the ChArUco case)
    partial = BoardView("partial", ids, true_corners_px(camera, BOARD, T)[ids])
    report = evaluate_gates(sparse_session([partial]), BOARD.object_points(), camera.image_size)
    assert "partial" not in {g.name for g in report.views}
    assert dict(report.unused_views)["partial"] == f"too few corners (6, need {MIN_TILT_CORNERS})"
    assert "partial: too few corners" in report.gate("observability").detail["views_not_used"][0]
    assert report.gate("tilt").detail["views_not_used"] == ["partial"]
    assert "1 view(s) too small or too sparse to read tilt" in report.gate("tilt").message


def test_a_view_whose_corners_span_too_small_an_area_is_not_used() -> None:
    camera = PinholeCamera.seed_reference((640, 480))
    T = place_board(camera, BOARD, tilt_rotation(math.radians(3.0), 0.0, 0.0), (320.0, 240.0), 1.2)
    ids = np.array([r * 9 + c for r in range(3) for c in range(3)])  # 9 corners, about 30 px across
    patch = BoardView("patch", ids, true_corners_px(camera, BOARD, T)[ids])
    report = evaluate_gates(sparse_session([patch]), BOARD.object_points(), camera.image_size)
    reason = dict(report.unused_views)["patch"]
    assert reason.startswith("corners span too small an area to read tilt (+/- ")
    assert report.gate("observability").detail["views_used"] == 12


@pytest.mark.parametrize(
    ("directions", "expected"),
    [
        ([], 0),
        ([10.0], 1),
        ([0.0, 45.0, 89.0], 1),
        ([0.0, 90.0], 2),
        ([0.0, 45.0, 90.0, 180.0], 3),
        ([0.0, 120.0, 240.0], 3),
        ([0.0, 90.0, 180.0, 270.0], 4),
        ([350.0, 80.0, 170.0, 260.0, 300.0], 4),
    ],
)
def test_distinct_directions_are_pairwise_at_least_90_degrees_apart(directions, expected) -> None:
    chosen = distinct_directions(directions)
    assert len(chosen) == expected
    for i, a in enumerate(chosen):
        for b in chosen[i + 1 :]:
            assert min(abs(a - b), 360.0 - abs(a - b)) >= 90.0 - 1e-9


def test_one_direction_with_25_degrees_of_scatter_counts_once_and_the_gate_fails() -> None:
    # the issue: tilts toward the left +-25 deg used to count as left, top left and bottom left
    camera = PinholeCamera.seed_reference((640, 480))
    rng = np.random.default_rng(5)
    views = []
    width, height = camera.image_size
    targets = [(x * width, y * height) for x in (0.2, 0.5, 0.8) for y in (0.2, 0.5, 0.8)]
    for i, direction_deg in enumerate(np.linspace(155.0, 205.0, 9)):
        R = tilt_rotation(math.radians(30.0), math.radians(direction_deg), float(rng.uniform(-0.2, 0.2)))
        T = place_board(camera, BOARD, R, targets[i], 0.45)
        views.append(BoardView(f"v{i}", np.arange(BOARD.n_corners), true_corners_px(camera, BOARD, T)))
    report = evaluate_gates(views, BOARD.object_points(), camera.image_size)
    tilt = report.gate("tilt")
    assert {g.direction_name for g in report.views} >= {"left", "top left", "bottom left"}  # the old 3
    assert not tilt.passed and tilt.value == 1.0 and tilt.reason == "tilt.directions"
    missing = tilt.detail["missing_directions"]
    assert missing[0] == "right" and missing[1] in ("top", "bottom")
    assert tilt.hint.startswith(f"tilt the board toward the right and {missing[1]}")
    lax = evaluate_gates(
        views, BOARD.object_points(), camera.image_size, GateThresholds(tilt_directions_min=1)
    )
    assert lax.gate("tilt").passed


def test_tilt_on_rendered_photos_through_calibctl_detection() -> None:
    from calibctl.core.capture.detect import detect_board
    from calibctl.core.synth.pinhole import render_view

    camera = PinholeCamera.seed_reference((640, 480))
    rng = np.random.default_rng(21)
    poses, truth = sweep_poses(camera, BOARD, 12, rng)
    views, kept = [], []
    for i, T in enumerate(poses):
        det, _ = detect_board(render_view(camera, BOARD, T, rng), BOARD)
        if det is not None:
            views.append(BoardView(f"v{i}", det.corner_ids, det.corners_px))
            kept.append(truth[i])
    assert len(views) >= 10
    report = evaluate_gates(views, BOARD.object_points(), camera.image_size)
    errors = np.array([g.tilt_deg for g in report.views]) - np.array(kept)
    assert len(report.views) == len(views)
    assert np.abs(errors).max() < TILT_ERR_MAX_DEG and errors.std() < TILT_SD_MAX_DEG


def test_a_session_of_only_sparse_views_reads_no_tilt_and_fails_observability_saying_why() -> None:
    camera = PinholeCamera.seed_reference((640, 480))
    views, _ = projected_session(camera, 13, n_views=10, tilt_deg=(20.0, 40.0))
    ids = np.array([0, 1, 2, 9, 10, 11])
    sparse = [BoardView(v.name, ids, v.corners_px[ids]) for v in views]
    report = evaluate_gates(sparse, BOARD.object_points(), camera.image_size)
    assert report.views == () and len(report.unused_views) == 10
    obs = report.gate("observability")
    assert not obs.passed and obs.value == 0.0 and obs.detail["views_used"] == 0
    assert len(obs.detail["views_not_used"]) == 10 and not report.gate("tilt").passed


# The 20-45 degree directions the tilt gate read on opencv-left-right's left01-left09 (2026-11-23): bottom,
# top, left, top left, bottom right (image y down: 90 = bottom). Only two are 90 degrees apart.
LEFT01_09_DIRECTIONS_DEG = [107.5, 252.6, 175.3, 241.9, 29.2]
COMPASS_DEG = [45.0 * b for b in range(8)]


def test_the_direction_asked_for_next_is_one_that_makes_the_gate_pass() -> None:
    assert len(distinct_directions(LEFT01_09_DIRECTIONS_DEG)) == 2
    (asked,) = directions_to_add(LEFT01_09_DIRECTIONS_DEG, COMPASS_DEG, 1)
    # the farthest-from-everything rule asked for 315 (top right): 74 deg from 29.2, still 2 directions
    assert len(distinct_directions([*LEFT01_09_DIRECTIONS_DEG, 315.0])) == 2
    assert len(distinct_directions([*LEFT01_09_DIRECTIONS_DEG, asked])) == 3


@pytest.mark.parametrize("seed", range(20))
def test_every_direction_asked_for_raises_the_count_when_one_can(seed: int) -> None:
    rng = np.random.default_rng(seed)
    have = list(rng.uniform(0.0, 360.0, rng.integers(1, 6)))
    for asked in directions_to_add(have, COMPASS_DEG, 3 - len(distinct_directions(have))):
        reachable = max(len(distinct_directions([*have, c])) for c in COMPASS_DEG)
        assert len(distinct_directions([*have, asked])) == reachable
        have.append(asked)


def test_a_fisheye_tilt_lens_is_the_projection_gates_fisheye_solve(monkeypatch):
    """A session the small lens cannot explain reads tilt through its fisheye solve; the projection gate,
    solving
    the same views as fisheye (--model fisheye, or a lens not known), gets that solve instead of solving
    again."""
    from calibctl.core.board.board_spec import chessboard_object_points
    from calibctl.core.board.views import BoardView
    from calibctl.core.capture.gates import evaluate_gates
    from calibctl.core.capture.projection_gate import solve_for_gate
    from calibctl.core.intrinsics import solve as solve_module
    from calibctl.core.intrinsics.recent_answers import RecentAnswers
    from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

    cam = FisheyeCamera.from_fov((640, 480), 150.0, circular=True)
    s = synthesize_fisheye_session(cam, 10, seed=1)
    model = chessboard_object_points(9, 6, 0.025)
    views = [
        BoardView(f"v{i}", np.arange(len(model)), np.asarray(p, np.float64))
        for i, p in enumerate(s.image_points_per_view)
    ]
    obj, px = [model[v.corner_ids] for v in views], [v.corners_px for v in views]
    solve_module.forget_recent_solves()
    computed: list[str] = []
    real = solve_module._solve
    monkeypatch.setattr(solve_module, "_solve", lambda *a: computed.append(a[3].name) or real(*a))
    with monkeypatch.context() as before:
        before.setattr(solve_module, "_RECENT", RecentAnswers(0))  # nothing remembered
        old = evaluate_gates(views, model, cam.image_size)
        old_gate = solve_for_gate(obj, px, cam.image_size, "fisheye")
    assert old.lens is not None and old.lens.fisheye and computed == ["fisheye", "fisheye"]
    report = evaluate_gates(views, model, cam.image_size)
    gate = solve_for_gate(obj, px, cam.image_size, "fisheye")
    assert computed == ["fisheye"] * 3  # the tilt's; the gate's was that one
    assert (report.gates, report.views) == (old.gates, old.views)  # the tilts read through the same lens
    assert np.array_equal(report.lens.camera_matrix, gate.camera_matrix)  # the very solve, reused
    # and the gate's own solve of before, to rounding: two solves of one input need not agree to the bit (on
    # the
    # oldest numpy / OpenCV pyproject.toml allows, sigma(cx) differed in the 10th digit)
    assert np.allclose(gate.camera_matrix, old_gate.camera_matrix, rtol=1e-9, atol=0.0)
    assert gate.sigma.keys() == old_gate.sigma.keys()
    assert all(np.isclose(gate.sigma[k], old_gate.sigma[k], rtol=1e-6, atol=0.0) for k in gate.sigma)
    solve_module.forget_recent_solves()


def test_the_centre_fixed_lens_fit_started_from_the_centre_free_one_lands_where_a_cold_start_does(
    monkeypatch,
):
    """The session's lens: when the centre-free fit keeps c at the centre within its noise, the centre-fixed
    fit starts from its focal length and distortion, and reaches the nominal start's minimum."""
    import cv2

    from calibctl.core.capture import tilt
    from calibctl.core.synth.corners import synthesize_session

    size = (640, 480)
    K = np.array([[780.0, 0.0, 319.5], [0.0, 780.0, 239.5], [0.0, 0.0, 1.0]])
    ses = synthesize_session(K, np.array([-0.28, 0.1, 0.0, 0.0, 0.0]), size, n_views=10, seed=4)
    obj, img = ses.object_points_per_view, ses.image_points_per_view
    calls: list[tuple[np.ndarray, int, np.ndarray | None]] = []
    fits: list = []
    real = tilt._calibrate

    def spy(o, i, s, K0, flags, D0=None):
        calls.append((K0.copy(), flags, D0))
        fits.append(real(o, i, s, K0, flags, D0))
        return fits[-1]

    monkeypatch.setattr(tilt, "_calibrate", spy)
    lens, _, _ = tilt.fit_session_lens(obj, img, size, None, "session")
    assert lens.source == "session" and len(calls) == 2
    free = fits[0]
    nominal = tilt.nominal_camera(size, math.hypot(*size))
    (K_start, flags, D_start) = calls[1]
    assert flags & cv2.CALIB_FIX_PRINCIPAL_POINT and free is not None
    assert K_start[0, 0] == free[1][0, 0] and np.array_equal(K_start[:2, 2], nominal[:2, 2])
    assert D_start is not None and np.array_equal(D_start, free[2])
    cold = real(obj, img, size, nominal, flags)
    assert cold is not None
    np.testing.assert_allclose(lens.camera_matrix, cold[1], rtol=1e-7)
    np.testing.assert_allclose(lens.dist_coeffs, cold[2], rtol=1e-6, atol=1e-9)
