"""Rig extrinsics on seeded corner-level rigs: truth within sigma, OpenCV and the joint LM agree,
loops close, bad input is refused with a message."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calibctl.core.extrinsics import rig_solve
from calibctl.core.extrinsics.rig_problem import RigViews
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_validation import loop_closures, validate_rig_holdout
from calibctl.core.extrinsics.se3 import rotation_angle_deg
from calibctl.errors import InconsistentDataError, NumericalError
from tests.core.rig_sessions import corner_session, true_members

CHI_6DOF_997 = 4.48  # sqrt of the 99.7 % quantile of chi-square with 6 degrees of freedom
Z_MAX = 3.0


def _edge_errors(truth, sol):
    for edge in sol.tree.edges:
        T_true = truth.T_root_cam[truth.names.index(edge.child)]
        err_mm = abs(edge.translation_mm - np.linalg.norm(T_true[:3, 3]) * 1e3)
        err_deg = rotation_angle_deg(edge.T_parent_child[:3, :3] @ T_true[:3, :3].T)
        yield edge, err_mm, err_deg


def test_opencv_stereo_and_joint_lm_find_the_same_minimum():
    _, views = corner_session(2, seed=2, baselines_m=(0.075,))
    members = true_members(_)
    cv = solve_rig(views, members, solver="opencv")
    lm = solve_rig(views, members, solver="lm")
    assert cv.solver == "cv2.stereoCalibrateExtended" and lm.solver == "calibctl joint LM"
    assert np.allclose(cv.T_a_b(1, 0), lm.T_a_b(1, 0), atol=1e-8)
    assert np.allclose(cv.covariance, lm.covariance, rtol=1e-4, atol=1e-14)


@pytest.mark.parametrize("n_cameras", [2, 3, 4])
def test_rig_recovers_truth_within_its_sigma(n_cameras):
    truth, views = corner_session(n_cameras, seed=10 + n_cameras)
    sol = solve_rig(views, true_members(truth))
    assert len(sol.tree.edges) == n_cameras - 1 and sol.tree.root == "CAM0"
    for edge, err_mm, err_deg in _edge_errors(truth, sol):
        assert err_mm < Z_MAX * edge.sigma_translation_mm, edge.child
        assert err_deg < Z_MAX * np.sqrt(3) * edge.sigma_rotation_deg, edge.child
        assert 0 < edge.sigma_translation_mm < 1.0


@pytest.mark.parametrize("n_cameras", [3, 4])
def test_pairwise_loops_close_within_their_sigma(n_cameras):
    truth, views = corner_session(n_cameras, seed=20 + n_cameras)
    loops = loop_closures(views, true_members(truth))
    assert len(loops) >= (1 if n_cameras == 3 else 3)
    for loop in loops:
        assert loop.mahalanobis < CHI_6DOF_997, loop
        assert loop.rotation_deg < Z_MAX * loop.sigma_rotation_deg
        assert loop.translation_mm < Z_MAX * loop.sigma_translation_mm


def test_a_broken_loop_is_seen():
    truth, views = corner_session(3, seed=23)
    members = true_members(truth)
    # camera 2's corners of the frames it shares with camera 0 only are shifted by 3 px: the pair
    # 0-2 then disagrees with 0-1-2 and the loop no longer closes
    rows = [list(r) for r in views.views]
    for row in rows:
        if row[2] is not None and row[1] is None:
            row[2] = type(row[2])(row[2].name, row[2].corner_ids, row[2].corners_px + [3.0, 0.0])
    shifted = RigViews(views.cameras, views.model_points_m, views.frames, tuple(tuple(r) for r in rows))
    assert max(loop.mahalanobis for loop in loop_closures(shifted, members)) > CHI_6DOF_997


def test_holdout_reports_every_camera_and_pair():
    truth, views = corner_session(3, seed=31)
    report = validate_rig_holdout(views, true_members(truth))
    assert report.n_folds >= 2
    assert all(0.2 < r < 0.4 for r in report.camera_rms_px)  # 0.2 px per coordinate -> 0.28 px 2-D
    assert {(p.a, p.b) for p in report.pairs} == {(0, 1), (0, 2), (1, 2)}
    for p in report.pairs:
        assert p.epipolar_rms_px < 0.5 and p.rectified_rms_px < 0.5 and p.epipolar_max_px >= p.epipolar_rms_px


def test_holdout_sees_a_wrong_baseline():
    truth, views = corner_session(2, seed=32, baselines_m=(0.075,))
    members = true_members(truth)
    good = validate_rig_holdout(views, members)
    wrong = list(members)
    wrong[1] = type(wrong[1])(
        wrong[1].name,
        wrong[1].camera_matrix * [[1.0], [1.03], [1.0]],
        wrong[1].dist_coeffs,
        wrong[1].image_size,
    )
    bad = validate_rig_holdout(views, wrong)
    assert bad.pairs[0].epipolar_rms_px > 2 * good.pairs[0].epipolar_rms_px


def test_refine_intrinsics_fixes_a_wrong_focal_length():
    truth, views = corner_session(2, seed=33, baselines_m=(0.075,), n_frames=25)
    members = true_members(truth)
    off = type(members[1])(
        members[1].name,
        members[1].camera_matrix * [[1.01], [1.01], [1.0]],
        members[1].dist_coeffs,
        members[1].image_size,
    )
    fixed = solve_rig(views, [members[0], off])
    refined = solve_rig(views, [members[0], off], refine_intrinsics=True)
    f_true = truth.cameras[1].K[0, 0]
    assert abs(refined.members[1].camera_matrix[0, 0] - f_true) < 0.2 * abs(off.camera_matrix[0, 0] - f_true)
    assert refined.rms_px[1] < fixed.rms_px[1]


def test_a_camera_that_shares_no_view_is_named():
    truth, views = corner_session(3, seed=34)
    rows = tuple((r[0], r[1], None) for r in views.views)
    with pytest.raises(NumericalError, match="CAM2 share no board view"):
        solve_rig(RigViews(views.cameras, views.model_points_m, views.frames, rows), true_members(truth))


def test_a_solve_that_explains_nothing_is_refused():
    truth, views = corner_session(2, seed=35)
    rng = np.random.default_rng(0)
    rows = tuple(
        (r[0], type(r[1])(r[1].name, rng.permutation(r[1].corner_ids), r[1].corners_px)) for r in views.views
    )
    with pytest.raises(NumericalError, match="diverged"):
        solve_rig(RigViews(views.cameras, views.model_points_m, views.frames, rows), true_members(truth))


def test_intrinsics_that_project_to_nan_are_refused_before_the_solve():
    """The shared solver (core.lm) refuses a start it cannot descend from, naming the rig solve."""
    truth, views = corner_session(3, seed=39)
    members = true_members(truth)
    members[2] = replace(members[2], dist_coeffs=np.array([np.nan, 0.0, 0.0, 0.0, 0.0]))
    with pytest.raises(NumericalError, match="the rig solve cannot start: .*NaN or infinite") as failed:
        solve_rig(views, members, solver="lm")
    assert failed.value.exit_code == 2 and "intrinsics belong to it" in (failed.value.hint or "")


def test_too_few_shared_frames_are_refused():
    truth, views = corner_session(2, seed=36)
    with pytest.raises(NumericalError, match="frame"):
        solve_rig(views.subset([0]), true_members(truth))


def _unsynchronised(views: RigViews) -> RigViews:
    """Camera 1's views shifted by three frames: each pair of photos shows two different board poses."""
    rows = [(r[0], views.views[(f + 3) % len(views.views)][1]) for f, r in enumerate(views.views)]
    return RigViews(views.cameras, views.model_points_m, views.frames, tuple(rows))


def test_frames_that_contradict_each_other_are_a_verdict_not_a_failure_to_run():
    """baka-stereo's webcams (neither rigid nor synchronised) used to exit 2 as if the tool had failed."""
    truth, views = corner_session(2, seed=37, n_frames=12)
    with pytest.raises(InconsistentDataError) as verdict:
        solve_rig(_unsynchronised(views), true_members(truth))
    assert verdict.value.exit_code == 1 and not isinstance(verdict.value, NumericalError)
    message = verdict.value.message
    assert "not rigid or not synchronised" in message and "CAM0-CAM1: per-frame baseline" in message
    assert "must not move against each other" in (verdict.value.hint or "")


def test_a_solver_that_fails_on_frames_that_agree_still_cannot_run(monkeypatch):
    truth, views = corner_session(2, seed=38, n_frames=12)
    real = rig_solve._stereo

    def turned(*args, **kwargs):  # a solver that returns camera 1 turned by 30 deg: not the data's fault
        cam_poses, board, members = real(*args, **kwargs)
        cam_poses[1, :3] += np.radians([0.0, 30.0, 0.0])
        return cam_poses, board, members

    monkeypatch.setattr(rig_solve, "_stereo", turned)
    with pytest.raises(NumericalError, match="diverged: .* the frames agree with one rigid rig") as failed:
        solve_rig(views, true_members(truth))
    assert failed.value.exit_code == 2 and not isinstance(failed.value, InconsistentDataError)
