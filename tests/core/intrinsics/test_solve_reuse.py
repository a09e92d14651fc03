"""Work the hot path of ``calibrate`` no longer does twice or for nothing, with the numbers unchanged:

* a solve asked again with the same corners, model and start is answered from the first ask (the capture's
  projection gate, then the solve's corner rule) - the very numbers a fresh solve computes;
* the model-misfit floor solves its lens models only when the fit could be a misfit; when it cannot, the
  lens-free floor is returned, never below the full floor, and the rule's verdict is the same;
* the fisheye focal guess scores a view at a focal length once: the folds' guesses, and their solves, are
  those computed with nothing remembered.
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest

from calibctl.core.intrinsics import fisheye_model, model_fit
from calibctl.core.intrinsics import solve as solve_module
from calibctl.core.intrinsics.fisheye_model import focal_guess_px, view_guess_rms_px
from calibctl.core.intrinsics.model_fit import (
    MISFIT_MIN_PX,
    can_misfit,
    check_model_misfit,
    detector_rms_px,
    noise_floor_px,
)
from calibctl.core.intrinsics.recent_answers import RecentAnswers
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.corners import synthesize_session
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session
from calibctl.errors import InputError


@pytest.fixture(autouse=True)
def fresh_cache():
    solve_module.forget_recent_solves()
    yield
    solve_module.forget_recent_solves()


@pytest.fixture
def computed(monkeypatch) -> list[str]:
    """The model of every solve really computed (a remembered answer is not)."""
    seen: list[str] = []
    real = solve_module._solve

    def spy(obj, img, size, m, initial, uncertainty, initial_dist=None):
        seen.append(m.name)
        return real(obj, img, size, m, initial, uncertainty, initial_dist)

    monkeypatch.setattr(solve_module, "_solve", spy)
    return seen


K_TRUE = np.array([[800.0, 0.0, 321.3], [0.0, 800.0, 238.7], [0.0, 0.0, 1.0]])
SIZE = (640, 480)


def _pinhole():
    """14 views at 0.1 px per coordinate: a k1k2 fit of ~0.14 px, which no floor can call a misfit."""
    s = synthesize_session(K_TRUE, np.array([-0.2814, 0.0977, 0, 0, 0]), SIZE, 14, seed=3, noise_px=0.1)
    return list(s.object_points_per_view), list(s.image_points_per_view), SIZE


def assert_same_solution(a, b) -> None:
    """Every field equal to the bit (arrays, dicts of floats, the covariance)."""
    for f in fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "covariance":
            assert (x is None) == (y is None)
            if x is not None:
                for g in fields(x):
                    u, v = getattr(x, g.name), getattr(y, g.name)
                    assert (
                        np.array_equal(u, v, equal_nan=True)
                        if isinstance(u, np.ndarray)
                        else (u == v or (isinstance(u, float) and math.isnan(u) and math.isnan(v)))
                    ), g.name
        elif f.name == "residuals_px":
            assert all(np.array_equal(p, q) for p, q in zip(x, y, strict=True))
        elif isinstance(x, np.ndarray):
            assert np.array_equal(x, y), f.name
        else:
            assert x == y, f.name


@pytest.mark.parametrize("model", ["k1k2", "rational", "fisheye"])
def test_a_solve_asked_twice_is_computed_once_and_is_the_solve_a_fresh_ask_computes(computed, model):
    obj, img, size = _pinhole()
    first = solve_intrinsics(obj, img, size, model)
    again = solve_intrinsics(
        [o.copy() for o in obj], [i.copy() for i in img], size, model
    )  # equal values hit
    assert again is first
    asked = len(computed)
    solve_module.forget_recent_solves()
    assert_same_solution(solve_intrinsics(obj, img, size, model), first)
    assert len(computed) == 2 * asked  # the second ask computed nothing; the fresh one did


def test_another_question_is_solved_again(computed):
    obj, img, size = _pinhole()
    base = solve_intrinsics(obj, img, size, "k1k2")
    moved = [i.copy() for i in img]
    moved[0][0, 0] += 0.01
    others = [
        solve_intrinsics(obj, moved, size, "k1k2"),  # one corner moved by 0.01 px
        solve_intrinsics(obj, img, size, "k1k2k3"),
        solve_intrinsics(obj, img, size, "k1k2", initial=np.array(base.camera_matrix)),
        solve_intrinsics(
            obj, img, size, "k1k2", uncertainty=False
        ),  # a fit: remembered apart, asked again below
    ]
    assert computed == ["k1k2", "k1k2", "k1k2k3", "k1k2", "k1k2"]
    assert all(o is not base for o in others)
    assert others[0].rms_px != base.rms_px and others[3].covariance is None
    assert solve_intrinsics(obj, img, size, "k1k2", uncertainty=False) is others[3] and len(computed) == 5


def test_the_fits_of_folds_never_push_out_a_sessions_solve(computed):
    obj, img, size = _pinhole()
    session = solve_intrinsics(obj, img, size, "k1k2")
    for k in range(solve_module.RECENT_FITS + 4):  # more distinct fits than are remembered
        solve_intrinsics(obj[:-1], [i + k * 1e-4 for i in img[:-1]], size, "k1k2", uncertainty=False)
    asked = len(computed)
    assert asked == 1 + solve_module.RECENT_FITS + 4
    assert solve_intrinsics(obj, img, size, "k1k2") is session and len(computed) == asked


def test_bad_input_still_gets_the_solves_own_error():
    obj, img, size = _pinhole()
    with pytest.raises(InputError):
        solve_intrinsics(obj, img[:-1], size, "k1k2")  # one view short: the solve's words, not a digest's
    with pytest.raises(InputError):
        solve_intrinsics(obj, [np.full_like(i, np.nan) for i in img], size, "k1k2")


def test_can_misfit_is_false_only_where_no_floor_could_fail_the_fit():
    assert not can_misfit(0.0) and not can_misfit(MISFIT_MIN_PX)
    assert can_misfit(np.nextafter(MISFIT_MIN_PX, 1.0)) and can_misfit(float("nan"))
    for fit in np.linspace(0.0, MISFIT_MIN_PX, 31):  # the claim itself, over floors from 0 up
        assert not any(model_fit.misfit(float(fit), floor) for floor in np.linspace(0.0, 1.0, 101))


def test_a_fit_that_cannot_be_a_misfit_reads_the_patch_alone_with_the_same_verdict(monkeypatch):
    obj, img, size = _pinhole()
    fit = solve_intrinsics(obj, img, size, "k1k2").rms_px
    assert fit <= MISFIT_MIN_PX
    full = noise_floor_px(obj, img, size)  # no fit given: both estimates, as before
    lens_solves: list[int] = []
    real = model_fit.lens_floor_px
    monkeypatch.setattr(model_fit, "lens_floor_px", lambda *a, **k: lens_solves.append(1) or real(*a, **k))
    quick = noise_floor_px(obj, img, size, fit)
    assert lens_solves == []
    # the lens-free floor, never above the fit it judges (which of the two is lower differs between numpy and
    # OpenCV builds: the oldest versions allowed read 0.160 px lens-free against a 0.136 px fit)
    assert quick == min(detector_rms_px(obj, img), fit) and quick >= min(full, fit)
    judged = [check_model_misfit(fit, floor, "k1k2") for floor in (full, quick)]
    assert [f.passed for f in judged] == [True, True] and [f.rule for f in judged] == ["model-misfit"] * 2


def test_a_fit_that_could_be_a_misfit_reads_the_full_floor():
    size = (1032, 778)  # k1k2 on a 150 deg circular fisheye: fit 1.6 px (test_model_fit)
    s = synthesize_fisheye_session(FisheyeCamera.from_fov(size, 150.0, True), 15, seed=0)
    obj, img = list(s.object_points_per_view), list(s.image_points_per_view)
    fit = solve_intrinsics(obj, img, size, "k1k2").rms_px
    assert can_misfit(fit)
    floor = noise_floor_px(obj, img, size, fit)
    assert floor == noise_floor_px(obj, img, size) < detector_rms_px(obj, img)
    assert not check_model_misfit(fit, floor, "k1k2").passed


@pytest.fixture
def scored(monkeypatch) -> list[float]:
    """The focal length of every fisheye focal-guess view score really computed (a remembered one is not)."""
    seen: list[float] = []
    real = fisheye_model._homography_rms_px

    def spy(obj_xy, img, f, centre):
        seen.append(float(f))
        return real(obj_xy, img, f, centre)

    monkeypatch.setattr(fisheye_model, "_homography_rms_px", spy)
    return seen


def _wide_fisheye(views: int = 15):
    cam = FisheyeCamera.from_fov((1280, 960), 170.0, circular=False)
    s = synthesize_fisheye_session(cam, views, seed=4)
    return list(s.object_points_per_view), list(s.image_points_per_view), cam.image_size


def test_a_focal_guess_asked_again_scores_no_view_again_and_guesses_the_same(scored, monkeypatch):
    obj, img, size = _wide_fisheye()
    folds = [[i for i in range(len(obj)) if i % 5 != k] for k in range(5)]  # validate_holdout's training sets
    with monkeypatch.context() as before:
        before.setattr(fisheye_model, "_RECENT_SCORES", RecentAnswers(0))  # nothing remembered
        fresh = [focal_guess_px([obj[i] for i in train], [img[i] for i in train], size) for train in folds]
    computed_fresh = len(scored)
    again = [focal_guess_px([obj[i] for i in train], [img[i] for i in train], size) for train in folds]
    assert again == fresh  # the very floats
    # the folds share most of their guess views, and the grid depends on the image size alone
    assert len(scored) - computed_fresh < computed_fresh / 2
    whole = focal_guess_px([o.copy() for o in obj], [i.copy() for i in img], size)
    asked = len(scored)
    assert focal_guess_px(obj, img, size) == whole and len(scored) == asked  # equal values hit


def test_a_view_score_is_remembered_for_its_exact_corners_and_focal_length_only(scored):
    obj, img, size = _wide_fisheye(4)
    first = view_guess_rms_px(obj, img, size, 500.0)
    assert len(scored) == 4
    moved = [i.copy() for i in img]
    moved[0][0, 0] += 1e-9
    scores = [
        view_guess_rms_px(obj, moved, size, 500.0),
        view_guess_rms_px(obj, img, size, np.nextafter(500.0, 1e3)),
        view_guess_rms_px(obj, img, (1281, 960), 500.0),
    ]  # another image centre
    assert len(scored) == 4 + 1 + 4 + 4
    assert np.array_equal(scores[0][1:], first[1:]) and not np.array_equal(scores[2], first)
    solve_module.forget_recent_solves()  # a benchmark's fresh round computes the scores again
    assert np.array_equal(view_guess_rms_px(obj, img, size, 500.0), first) and len(scored) == 17


def test_the_fisheye_solves_of_the_folds_are_those_computed_without_remembered_scores(monkeypatch):
    obj, img, size = _wide_fisheye()
    train = [i for i in range(len(obj)) if i % 5 != 0]
    solve_intrinsics(obj, img, size, "fisheye")  # the session's solve scores most of the fold's guess views
    fold = solve_intrinsics(
        [obj[i] for i in train], [img[i] for i in train], size, "fisheye", uncertainty=False
    )
    solve_module.forget_recent_solves()
    monkeypatch.setattr(fisheye_model, "_RECENT_SCORES", RecentAnswers(0))
    assert_same_solution(
        solve_intrinsics(
            [obj[i] for i in train], [img[i] for i in train], size, "fisheye", uncertainty=False
        ),
        fold,
    )
