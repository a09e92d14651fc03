"""One camera or two? The held-out split test, on the real stereo folder and on seeded sessions."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import camera_split
from calibctl.core.capture.camera_split import (
    CAPTURE_MAX_VIEWS,
    TWO_CAMERA_RATIO,
    check_one_camera,
    min_views_to_split,
    one_camera_gate,
    spread_views,
)
from calibctl.core.capture.detect import detect_board
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.corners import synthesize_session
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session
from tests.datasets import BAKA_STEREO, LEFT_RIGHT, require_datasets

BOARD = BoardSpec.chessboard(9, 6, 1.0)
D = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])


def K(f: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def stereo_folder():
    """(names, object points, corners) of every image in opencv-left-right, calibctl's detector."""
    require_datasets()
    names, obj, img = [], [], []
    for path in sorted(LEFT_RIGHT.glob("*.jpg")):
        det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), BOARD)
        assert det is not None, path.name  # DATASET.md: 13/13 left and right
        names.append(path.name)
        obj.append(BOARD.object_points()[det.corner_ids])
        img.append(det.corners_px)
    return names, obj, img


def test_the_left_and_right_folder_is_two_cameras_split_exactly(stereo_folder):
    names, obj, img = stereo_folder
    split = check_one_camera(obj, img, (640, 480))
    assert split is not None and split.suspected and split.ratio >= TWO_CAMERA_RATIO
    assert {names[i][:4] for i in split.group_a} == {"left"} and len(split.group_a) == 13
    assert {names[i][:5] for i in split.group_b} == {"right"} and len(split.group_b) == 13
    # each group's camera is the camera a plain OpenCV solve of that camera's files finds
    for group, camera in ((split.group_a, split.camera_a), (split.group_b, split.camera_b)):
        _, K_plain, _, _, _ = cv2.calibrateCamera(
            [obj[i].astype(np.float32) for i in group],
            [img[i].astype(np.float32) for i in group],
            (640, 480),
            None,
            None,
        )
        assert abs(camera[0, 2] - K_plain[0, 2]) < 3.0 and abs(camera[0, 0] - K_plain[0, 0]) < 5.0
    assert abs(split.camera_a[0, 2] - split.camera_b[0, 2]) > 10.0  # cx: 342 vs 326 px


@pytest.mark.parametrize("camera", ["left", "right"])
def test_each_camera_alone_is_one_camera(stereo_folder, camera):
    names, obj, img = stereo_folder
    mine = [i for i, n in enumerate(names) if n.startswith(camera)]
    split = check_one_camera([obj[i] for i in mine], [img[i] for i in mine], (640, 480))
    assert split is not None and not split.suspected and split.ratio < TWO_CAMERA_RATIO


def test_two_seeded_cameras_in_one_session_are_found_and_one_camera_is_not() -> None:
    # focal lengths 4 % apart at 0.1 px noise (the real pair: 0.8 % in f, 15 px in c, k2/k3 differ)
    one = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), 12, seed=1, noise_px=0.1)
    other = synthesize_session(K(832.0, 321.3, 238.7), D, (640, 480), 12, seed=2, noise_px=0.1)
    obj = [*one.object_points_per_view, *other.object_points_per_view]
    img = [*one.image_points_per_view, *other.image_points_per_view]
    order = np.random.default_rng(0).permutation(24)  # interleaved, not two blocks
    split = check_one_camera([obj[i] for i in order], [img[i] for i in order], (640, 480))
    assert split is not None and split.suspected
    assert {int(order[i]) < 12 for i in split.group_a} == {order[split.group_a[0]] < 12}  # pure groups
    same = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), 24, seed=3, noise_px=0.1)
    clean = check_one_camera(same.object_points_per_view, same.image_points_per_view, (640, 480))
    assert clean is not None and not clean.suspected


def test_a_session_too_small_to_split_is_not_judged() -> None:
    ses = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), 9, seed=4)
    assert check_one_camera(ses.object_points_per_view, ses.image_points_per_view, (640, 480)) is None


def test_a_principal_point_shift_alone_is_absorbed_by_the_poses() -> None:
    """The documented limit: a camera that differs only by a 20 px shift of c predicts the other's views
    almost as well (each view's pose re-fit absorbs most of it), so this is not called two cameras."""
    one = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), 12, seed=1, noise_px=0.2)
    other = synthesize_session(K(800.0, 341.3, 228.7), D, (640, 480), 12, seed=2, noise_px=0.2)
    split = check_one_camera(
        [*one.object_points_per_view, *other.object_points_per_view],
        [*one.image_points_per_view, *other.image_points_per_view],
        (640, 480),
    )
    assert split is not None and split.group_a == tuple(range(12))  # the split itself is found
    assert not split.suspected


# the capture gate ----------------------------------------------------------------------------------


def test_the_capture_gate_fails_the_mixed_folder_with_a_hint_and_passes_each_camera(stereo_folder):
    names, obj, img = stereo_folder
    mixed = one_camera_gate(obj, img, names, (640, 480))
    assert not mixed.passed and mixed.gate == "one_camera" and mixed.reason == "one_camera.two_cameras"
    assert mixed.value >= TWO_CAMERA_RATIO and mixed.threshold == TWO_CAMERA_RATIO
    assert "two cameras" in mixed.hint and "--source 'left*.jpg'" in mixed.hint  # type: ignore[operator]
    assert (
        float(mixed.detail["ratio_k1k2"]) >= TWO_CAMERA_RATIO
        and float(mixed.detail["ratio_fisheye"]) >= TWO_CAMERA_RATIO
    )
    assert sorted(mixed.detail["group_a"]) == sorted(n for n in names if n.startswith("left"))  # type: ignore[arg-type]
    for camera in ("left", "right"):
        mine = [i for i, n in enumerate(names) if n.startswith(camera)]
        alone = one_camera_gate(
            [obj[i] for i in mine], [img[i] for i in mine], [names[i] for i in mine], (640, 480)
        )
        assert alone.passed and 0.0 < alone.value < TWO_CAMERA_RATIO and alone.reason is None


def test_the_capture_gate_spreads_its_views_over_a_long_session(stereo_folder):
    """Capped at fewer views than the folder has, it still sees both halves (left* then right*)."""
    names, obj, img = stereo_folder
    capped = one_camera_gate(obj, img, names, (640, 480), max_views=16)
    assert capped.detail["views_checked"] == 16 and not capped.passed


def test_the_views_checked_are_spread_evenly_first_and_last_included() -> None:
    assert spread_views(12, 16) == list(range(12))
    picked = spread_views(96)
    assert len(picked) == CAPTURE_MAX_VIEWS and picked[0] == 0 and picked[-1] == 95
    assert picked == sorted(set(picked)) and max(np.diff(picked)) <= 2  # no gap wider than the even step


def test_the_capture_gate_passes_a_session_too_small_to_check_and_says_so() -> None:
    too_few = max(min_views_to_split(m) for m in camera_split.CAPTURE_MODELS) - 1
    ses = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), too_few, seed=4)
    gate = one_camera_gate(
        ses.object_points_per_view,
        ses.image_points_per_view,
        [f"v{i}" for i in range(len(ses.image_points_per_view))],
        (640, 480),
    )
    assert gate.passed and gate.value == 0.0 and str(gate.detail["summary"]).startswith("not checked")


def test_one_wide_angle_lens_is_not_two_cameras_at_capture() -> None:
    """k1k2 misfits a 120-degree fisheye and its best split reads 1.47 (over the threshold); the gate
    confirms under the fisheye model (1.01) and passes."""
    ses = synthesize_fisheye_session(FisheyeCamera.from_fov((1280, 960), 120.0), 24, seed=1)
    obj, img = ses.object_points_per_view, ses.image_points_per_view
    k1k2 = check_one_camera(obj, img, (1280, 960), "k1k2")
    assert k1k2 is not None and k1k2.suspected  # the misreading the confirmation is there for
    gate = one_camera_gate(obj, img, [f"v{i}" for i in range(24)], (1280, 960))
    assert gate.passed and gate.value < TWO_CAMERA_RATIO <= float(gate.detail["ratio_k1k2"])


def _baka(folders: tuple[str, ...]):
    board = BoardSpec.chessboard(7, 10, 1.0)
    names, obj, img = [], [], []
    for folder in folders:
        for path in sorted((BAKA_STEREO / folder).glob("*.jpg")):
            det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), board)
            if det is not None and (det.edge_width_px or 0.0) <= 8.0:  # what capture accepts (blur limit)
                names.append(path.name)
                obj.append(board.object_points()[det.corner_ids])
                img.append(det.corners_px)
    return names, obj, img


def test_baka_stereo_left_alone_is_not_flagged() -> None:
    require_datasets()
    names, obj, img = _baka(("left",))
    assert len(names) >= min_views_to_split()
    gate = one_camera_gate(obj, img, names, (1280, 720))
    assert gate.passed and gate.value < TWO_CAMERA_RATIO


@pytest.mark.parametrize("seed", [1, 4])
def test_near_frontal_views_that_fit_any_focal_length_are_no_second_camera(seed) -> None:
    # one camera with non-square pixels (fx/fy 1.06: k1k2 cannot fit it), 6 views tilted 25-40 deg and 8
    # within 3 deg of frontal: the frontal group "solves" at fx 21 000-29 000 px and predicted its own views
    # 4.3x / 6.8x better than the tilted group's camera (measured, seeds 1 / 4): a two-camera verdict,
    # as on real phone-video frames (ratio 3.15, the frontal group's fx 6806). That group cannot observe
    # its own intrinsics (the observability gate's sigma5 / sigma1 < 1e-4), so the split is not judged.
    K = np.array([[1060.0, 0.0, 480.0], [0.0, 1000.0, 270.0], [0.0, 0.0, 1.0]])
    dist, size = np.array([0.05, -0.1, 0.0, 0.0, 0.0]), (960, 540)
    tilted = synthesize_session(K, dist, size, 6, seed=seed, tilt_deg=(25.0, 40.0), distance_m=(0.45, 0.7))
    frontal = synthesize_session(
        K, dist, size, 8, seed=100 + seed, tilt_deg=(0.0, 3.0), distance_m=(0.45, 0.7)
    )
    obj = [*tilted.object_points_per_view, *frontal.object_points_per_view]
    img = [*tilted.image_points_per_view, *frontal.image_points_per_view]
    assert check_one_camera(obj, img, size, "k1k2") is None
    gate = one_camera_gate(obj, img, [f"v{i}" for i in range(len(obj))], size)
    assert gate.passed and "observe their own intrinsics" in gate.message


def test_a_split_that_does_not_settle_is_scored_on_the_groups_it_was_solved_from(monkeypatch) -> None:
    """Stopped after MAX_ROUNDS, the split handed to the held-out test must be the one the two solves
    were made from (it once handed over the next assignment: "the fit has 47 views but 48 were given")."""
    one = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), 12, seed=1, noise_px=0.1)
    other = synthesize_session(K(832.0, 321.3, 238.7), D, (640, 480), 12, seed=2, noise_px=0.1)
    obj = [*one.object_points_per_view, *other.object_points_per_view]
    img = [*one.image_points_per_view, *other.image_points_per_view]
    monkeypatch.setattr(camera_split, "MAX_ROUNDS", 1)  # the halves start is then never re-assigned
    order = np.random.default_rng(0).permutation(24)  # interleaved: the first round wants to move views
    obj, img = [obj[i] for i in order], [img[i] for i in order]
    split = check_one_camera(obj, img, (640, 480))
    assert split is not None and sorted(split.group_a + split.group_b) == list(range(24))
    for group, camera in ((split.group_a, split.camera_a), (split.group_b, split.camera_b)):
        alone = solve_intrinsics([obj[i] for i in group], [img[i] for i in group], (640, 480), "k1k2")
        np.testing.assert_allclose(camera, alone.camera_matrix, rtol=1e-9)


def test_the_same_question_is_answered_once(monkeypatch) -> None:
    """calibrate asks twice (the capture gate, then the solve) with the same corners: the second answer is
    the first, found by the values (copies hit), and any change in corners, model or threshold is asked
    anew."""
    session = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), 20, seed=3, noise_px=0.1)
    obj, img = session.object_points_per_view, session.image_points_per_view
    calls = []
    real = camera_split._check_one_camera
    monkeypatch.setattr(camera_split, "_check_one_camera", lambda *a: calls.append(a) or real(*a))
    first = check_one_camera(obj, img, (640, 480))
    again = check_one_camera(
        [o.copy() for o in obj], [np.array(i, dtype=np.float64) for i in img], (640, 480)
    )
    assert first is not None and again is first and len(calls) == 1
    moved = [i.copy() for i in img]
    moved[5][7, 0] += 1e-6
    assert check_one_camera(obj, moved, (640, 480)) is not first and len(calls) == 2
    check_one_camera(obj, img, (640, 480), "k1k2k3")
    check_one_camera(obj, img, (640, 480), threshold=1.2)
    assert len(calls) == 4
    for k in range(camera_split.RECENT_CHECKS):  # the oldest answer is forgotten, never the store grows
        check_one_camera(obj, img, (640, 480), threshold=1.5 + k)
    assert len(camera_split._RECENT) == camera_split.RECENT_CHECKS
    check_one_camera(obj, img, (640, 480))
    assert len(calls) == 5 + camera_split.RECENT_CHECKS


def _rounds_with_and_without_settling(monkeypatch, obj, img, size):
    """(split with the early stop, split with it off): the memo is forgotten between the two, its key not
    holding the module's constants."""
    camera_split.forget_recent_checks()
    settled = check_one_camera(obj, img, size)
    monkeypatch.setattr(
        camera_split, "SETTLED_GAIN", 0.0
    )  # no reassignment gains less than nothing: never settled
    camera_split.forget_recent_checks()
    full = check_one_camera(obj, img, size)
    camera_split.forget_recent_checks()
    assert settled is not None and full is not None
    return settled, full


def test_one_camera_stops_alternating_once_only_noise_would_move(monkeypatch) -> None:
    """One camera's views swap between two near-identical cameras: without the stop this session takes
    several rounds to settle; with it the alternation ends after its second round (the first is never
    judged) on a split that is still one camera."""
    same = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), 24, seed=30, noise_px=0.1)
    settled, full = _rounds_with_and_without_settling(
        monkeypatch, same.object_points_per_view, same.image_points_per_view, (640, 480)
    )
    assert full.rounds > settled.rounds >= 2
    assert not settled.suspected and not full.suspected
    assert sorted(settled.group_a + settled.group_b) == list(range(24))


def test_two_cameras_drifting_apart_slowly_are_not_stopped(monkeypatch) -> None:
    """Alternating views of two cameras 4 % apart in f start from two blends and drift for rounds that gain
    little before they separate: the stop must not end that drift, so the split, its ratio and its rounds
    are those of the alternation run to its end."""
    n = 30
    one = synthesize_session(K(800.0, 321.3, 238.7), D, (640, 480), n, seed=60, noise_px=0.1)
    other = synthesize_session(K(832.0, 321.3, 238.7), D, (640, 480), n, seed=70, noise_px=0.1)
    order = [k for pair in zip(range(n), range(n, 2 * n), strict=True) for k in pair]  # a0 b0 a1 b1 ...
    obj = [[*one.object_points_per_view, *other.object_points_per_view][k] for k in order]
    img = [[*one.image_points_per_view, *other.image_points_per_view][k] for k in order]
    settled, full = _rounds_with_and_without_settling(monkeypatch, obj, img, (640, 480))
    assert full.suspected and full.rounds >= 3
    assert (settled.group_a, settled.rounds, settled.ratio) == (full.group_a, full.rounds, full.ratio)
    assert (
        len({order[i] < n for i in settled.group_a}) == 1 and len(settled.group_a) == n
    )  # one camera, all of it


def test_a_split_with_no_residual_or_a_non_finite_one_never_settles() -> None:
    in_a = np.arange(10) < 5
    corners = np.full(10, 54.0)
    assert not camera_split._settled(in_a, np.zeros(10), np.zeros(10), corners, TWO_CAMERA_RATIO)
    nan = np.full(10, 0.1)
    nan[3] = np.nan
    assert not camera_split._settled(in_a, nan, np.full(10, 0.1), corners, TWO_CAMERA_RATIO)
    # the same figures without the defect settle: what refused above was the guard
    assert camera_split._settled(in_a, np.full(10, 0.1), np.full(10, 0.1), corners, TWO_CAMERA_RATIO)
