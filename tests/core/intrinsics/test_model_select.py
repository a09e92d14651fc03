"""--model auto: the seed's 10 % / held-out outer-ring rule on lenses of known distortion."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.intrinsics import model_select
from calibctl.core.intrinsics.model_select import ALTERNATIVES, LADDER, MIN_FIT_IMPROVEMENT, select_model
from calibctl.core.synth.corners import synthesize_session
from calibctl.errors import NumericalError
from tests.datasets import LEFT_RIGHT, needs_datasets

SIZE = (640, 480)


def _session(f_px: float, dist, seed: int = 41, n_views: int = 12):
    K = np.array([[f_px, 0.0, 321.3], [0.0, f_px, 238.7], [0.0, 0.0, 1.0]])
    scale = f_px / 800.0  # keep the board filling the frame at any focal length
    ses = synthesize_session(
        K,
        np.array(dist, dtype=float),
        SIZE,
        n_views=n_views,
        seed=seed,
        distance_m=(0.35 * scale, 0.6 * scale),
    )
    return ses.object_points_per_view, ses.image_points_per_view


def _check_trail_consistency(selection):
    assert [c.model for c in selection.trail] == [*LADDER, *ALTERNATIVES]  # fisheye is considered, not taken
    accepted = [c.model for c in selection.trail if c.accepted]
    assert selection.chosen == accepted[-1] == selection.solution.model == selection.holdout.model
    current = "k1k2"
    for c in selection.trail[1:]:
        base = LADDER[0] if c.model in ALTERNATIVES else current  # another lens family is compared with k1k2
        assert c.compared_to == base
        if c.fit_improvement_frac is not None:
            # the verdict follows the rule from the recorded numbers
            prev = next(p for p in selection.trail if p.model == base)
            rule = (
                c.fit_improvement_frac >= MIN_FIT_IMPROVEMENT
                and c.holdout_outer_rms_px <= prev.holdout_outer_rms_px
            )
            if (
                c.model in ALTERNATIVES and current != base
            ):  # ... and predict no worse than the ladder's choice
                chosen = next(p for p in selection.trail if p.model == current)
                rule = rule and c.holdout_outer_rms_px <= chosen.holdout_outer_rms_px
            assert c.accepted == rule
        if c.accepted:
            current = c.model


def test_a_two_coefficient_lens_keeps_k1k2():
    sel = select_model(*_session(800.0, [-0.2814, 0.0977, 0, 0, 0]), SIZE)
    assert sel.chosen == "k1k2"
    _check_trail_consistency(sel)
    k3 = sel.trail[1]
    assert not k3.accepted and k3.fit_improvement_frac < 0.01
    assert "needs >= 10 %" in k3.reason


def test_the_same_question_is_answered_once(monkeypatch):
    """calibrate --model auto --reference-distance asks at capture (the gauge's lens) and at the solve, with
    the same corners: the second answer is the first, found by the values; other corners are asked anew."""
    obj, img = _session(800.0, [-0.2814, 0.0977, 0, 0, 0])
    calls = []
    real = model_select._select_model
    monkeypatch.setattr(model_select, "_select_model", lambda *a: calls.append(a) or real(*a))
    first = select_model(obj, img, SIZE)
    again = select_model([o.copy() for o in obj], [np.array(i, dtype=np.float64) for i in img], SIZE)
    assert again is first and len(calls) == 1
    moved = [i.copy() for i in img]
    moved[3][5, 1] += 1e-6
    assert select_model(obj, moved, SIZE) is not first and len(calls) == 2
    select_model(obj, img, SIZE, ladder=LADDER[:2])
    assert len(calls) == 3


def test_a_strong_k3_lens_earns_k3_and_nothing_more():
    # 18 views: with 12 this lens's k3 improves the fit RMS by only 9.5 % (held-out outer ring
    # 0.47 -> 0.27 px) and the rule keeps k1k2; see the module docstring of model_select
    sel = select_model(*_session(450.0, [-0.35, 0.15, 0, 0, -0.1], n_views=18), SIZE)
    assert sel.chosen == "k1k2k3"
    _check_trail_consistency(sel)
    assert sel.trail[1].fit_improvement_frac > 0.2
    assert sel.solution.dist_coeffs[4] == pytest.approx(-0.1, abs=0.03)


def test_a_decentred_lens_earns_the_tangential_terms_even_after_k3_is_rejected():
    sel = select_model(*_session(800.0, [-0.2814, 0.0977, 0.006, -0.004, 0]), SIZE)
    assert sel.chosen == "k1k2p1p2k3"
    _check_trail_consistency(sel)
    assert not sel.trail[1].accepted and sel.trail[2].compared_to == "k1k2"
    np.testing.assert_allclose(sel.solution.dist_coeffs[2:4], [0.006, -0.004], atol=5e-4)


def test_rungs_that_need_more_views_are_recorded_as_not_solvable():
    sel = select_model(*_session(800.0, [-0.2814, 0.0977, 0, 0, 0], n_views=4), SIZE)
    assert sel.chosen == "k1k2"
    by_model = {c.model: c for c in sel.trail}
    assert by_model["k1k2p1p2k3"].reason.startswith("not solvable: held-out validation needs at least 5")
    assert by_model["rational"].reason.startswith("not solvable: model rational needs at least 5 board views")
    assert by_model["rational"].fit_rms_px is None and not by_model["rational"].accepted


def test_too_few_views_for_the_starting_model_is_an_error():
    obj, img = _session(800.0, [-0.2814, 0.0977, 0, 0, 0], n_views=3)
    with pytest.raises(NumericalError, match="held-out validation needs at least 4 views, got 3"):
        select_model(obj, img, SIZE)


def test_auto_switches_to_fisheye_for_a_wide_lens():
    # measured: rational is accepted on the ladder first; fisheye beats k1k2 by the rule and rational too
    from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

    size = (1280, 960)
    s = synthesize_fisheye_session(FisheyeCamera.from_fov(size, 170.0, circular=True), 12, seed=8)
    sel = select_model(s.object_points_per_view, s.image_points_per_view, size)
    assert sel.chosen == "fisheye"
    assert sel.trail[-1].model == "fisheye" and sel.trail[-1].accepted and sel.trail[-1].compared_to == "k1k2"
    _check_trail_consistency(sel)


@pytest.mark.parametrize("seed", [1, 41])
def test_non_square_pixels_earn_fx_and_fy_apart(seed):
    # frames resized in one axis (fx/fy = 1.06, as measured on real phone-video frames): every other rung
    # ties fx to fy; opencv-default frees them and passes the 10 % / held-out rule against the ladder.
    # Fisheye frees them too and then competes on held-out error: seed 1 opencv-default predicts the outer
    # ring 5 % better (measured 0.363 against 0.380 px) and stays; seed 41 is a tie (0.29107 against
    # 0.29104 px) that either may win. Whichever is chosen solves fx and fy apart.
    K = np.array([[848.0, 0.0, 321.3], [0.0, 800.0, 238.7], [0.0, 0.0, 1.0]])
    ses = synthesize_session(
        K, np.array([-0.2814, 0.0977, 0, 0, 0]), SIZE, n_views=14, seed=seed, distance_m=(0.35, 0.6)
    )
    sel = select_model(ses.object_points_per_view, ses.image_points_per_view, SIZE)
    assert next(c for c in sel.trail if c.model == "opencv-default").accepted
    assert sel.chosen in ("opencv-default", "fisheye") and (seed != 1 or sel.chosen == "opencv-default")
    fx, fy = sel.solution.camera_matrix[0, 0], sel.solution.camera_matrix[1, 1]
    assert fx / fy == pytest.approx(1.06, abs=0.005)
    _check_trail_consistency(sel)


def test_fisheye_beats_a_rational_model_that_fits_as_well_but_predicts_worse():
    # 180 deg full-frame fisheye, seed 4 (measured): rational is the ladder's choice and fits the corners it
    # was solved on as well as fisheye (0.2714 against 0.2715 px), but predicts the held-out outer ring at
    # 0.61 px against fisheye's 0.27. A fit-RMS comparison across the two lens families chose rational.
    from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

    size = (640, 640)
    s = synthesize_fisheye_session(FisheyeCamera.from_fov(size, 180.0, circular=False), 15, seed=4)
    sel = select_model(s.object_points_per_view, s.image_points_per_view, size)
    trail = {c.model: c for c in sel.trail}
    assert trail["rational"].accepted and sel.chosen == "fisheye"
    assert trail["fisheye"].holdout_outer_rms_px < 0.5 * trail["rational"].holdout_outer_rms_px
    assert "is not compared across lens families" in trail["fisheye"].reason
    _check_trail_consistency(sel)


@needs_datasets
def test_real_pinhole_photos_keep_k1k2_and_fisheye_is_judged_against_k1k2():
    # measured (opencv-left-right left, 13 views): fisheye +0.9 % fit RMS over k1k2, held-out outer ring worse
    import cv2

    from calibctl.core.board.board_spec import BoardSpec
    from calibctl.core.capture.detect import detect_board

    spec = BoardSpec.chessboard(9, 6, 0.025)
    obj, img = [], []
    for path in sorted(LEFT_RIGHT.glob("left*.jpg")):
        det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), spec)
        if det is not None:
            obj.append(spec.object_points()[det.corner_ids])
            img.append(det.corners_px)
    sel = select_model(obj, img, SIZE)
    assert sel.chosen == "k1k2"
    fisheye = sel.trail[-1]
    assert fisheye.model == "fisheye" and not fisheye.accepted and fisheye.compared_to == "k1k2"
    _check_trail_consistency(sel)


def _strong_fisheye_session():
    """185 deg circular fisheye, 12 views of a 12 x 9 board held close (seed 1): k1k2 cannot explain it
    (measured: full k1k2 solve RMS 10.9 px, over the 10 px limit of solve_intrinsics)."""
    from calibctl.core.synth.fisheye import (
        FisheyeCamera,
        default_fisheye_distance_m,
        synthesize_fisheye_session,
    )

    size = (1032, 778)
    cam = FisheyeCamera.from_fov(size, 185.0, circular=True)
    near, far = default_fisheye_distance_m(cam, 0.025)
    s = synthesize_fisheye_session(
        cam, 12, seed=1, max_view_deg=80.0, cols=12, rows=9, distance_m=(0.5 * near, 0.5 * far)
    )
    return s, size


def test_a_rung_that_cannot_be_solved_is_out_and_auto_still_reaches_fisheye():
    s, size = _strong_fisheye_session()
    sel = select_model(s.object_points_per_view, s.image_points_per_view, size)
    trail = {c.model: c for c in sel.trail}
    assert [c.model for c in sel.trail] == [
        *LADDER,
        *ALTERNATIVES,
    ]  # every rung and the fisheye branch walked
    assert not trail["k1k2"].accepted and trail["k1k2"].reason.startswith("not solvable: ")
    assert "does not explain the corners" in trail["k1k2"].reason
    start = next(c for c in sel.trail if c.compared_to is None and c.accepted)
    assert start.model != "k1k2" and "k1k2 not solvable" in start.reason
    assert (
        sel.chosen == "fisheye" and trail["fisheye"].accepted and trail["fisheye"].compared_to == start.model
    )
    assert sel.solution.rms_px < 0.5  # the render's noise is 0.2 px per coordinate


def test_no_model_at_all_is_an_error_naming_every_rung():
    obj, img = _session(800.0, [-0.2814, 0.0977, 0, 0, 0], n_views=3)
    with pytest.raises(NumericalError) as err:
        select_model(obj, img, SIZE)
    assert err.value.message.startswith("no model can be solved and validated on these corners: k1k2: ")
    assert all(f"{m}: " in err.value.message for m in (*LADDER, *ALTERNATIVES))
