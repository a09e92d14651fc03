"""Loop closure judged with the cross covariances of pair solves that share corners
(core.extrinsics.rig_loop):
the joint covariance agrees with each pair's own, predicts the spread of the loop residual over repeated noise
on one rig, and a broken loop is seen."""

from __future__ import annotations

import numpy as np

from calibctl.core.extrinsics.rig_loop import loop_covariance
from calibctl.core.extrinsics.rig_problem import RigViews
from calibctl.core.extrinsics.rig_tree import T_to_pose, pose_to_T, propagate
from calibctl.core.extrinsics.rig_validation import loop_closures, pairwise_solutions
from calibctl.core.extrinsics.se3 import invert
from calibctl.core.synth.rig import rig_corners, synthesize_rig
from tests.core.rig_sessions import BOARD, corner_session, true_members, views_from

CHI_6DOF_997 = 4.48
NOISE_PX = 0.2


def _triangle(views: RigViews, members):
    """The 0-1-2 loop: its pair solutions, x, the residual function."""
    pairs = pairwise_solutions(views, members)
    sols = [pairs[(0, 1)], pairs[(1, 2)], pairs[(0, 2)]]
    x = np.concatenate([s.cam_poses[1] for s in sols])

    def around(v: np.ndarray) -> np.ndarray:  # T_0_1 T_1_2 T_2_0; each pair's x is T_hi_lo
        p01, p12, p02 = np.split(v, 3)
        return T_to_pose(invert(pose_to_T(p01)) @ invert(pose_to_T(p12)) @ pose_to_T(p02))

    return sols, x, around


def test_the_joint_covariance_holds_each_pairs_own_on_its_diagonal():
    truth, views = corner_session(3, seed=41)
    sols, x, around = _triangle(views, true_members(truth))
    # the identity as the "loop": the propagated joint covariance is the joint covariance of x itself
    joint = loop_covariance(sols, views, lambda v: v, x).jacobian
    for i, s in enumerate(sols):
        own = s.jacobian_covariance if s.jacobian_covariance is not None else s.covariance
        assert np.allclose(joint[6 * i : 6 * i + 6, 6 * i : 6 * i + 6], own, rtol=1e-6, atol=1e-14)
    # pairs 0-1 and 1-2 share camera 1's corners: correlated, which the independent treatment set to 0
    sd = np.sqrt(np.diag(joint))
    correlation = joint / np.outer(sd, sd)
    assert np.abs(correlation[0:6, 6:12]).max() > 0.1


def test_the_joint_covariance_predicts_the_loop_residual_over_repeated_noise():
    rng = np.random.default_rng(42)
    truth = synthesize_rig(3, BOARD, 16, rng, min_cameras=3)
    members = true_members(truth)
    residuals, predicted, independent = [], [], []
    for _ in range(40):
        views = views_from(truth, rig_corners(truth, BOARD, NOISE_PX, rng))
        sols, x, around = _triangle(views, members)
        residuals.append(around(x))
        predicted.append(loop_covariance(sols, views, around, x).jacobian)
        block = np.zeros((18, 18))
        for i, s in enumerate(sols):
            block[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = s.covariance
        independent.append(propagate(around, x, block))
    r = np.array(residuals)
    empirical = r.T @ r / len(r)  # the loop closes exactly without noise: the mean is 0
    cov = np.mean(predicted, axis=0)
    ratio = np.trace(np.linalg.solve(cov, empirical)) / 6
    assert 0.7 < ratio < 1.4, ratio
    # treated as independent the pairs predict a residual several times wider than it is
    assert np.trace(np.linalg.solve(np.mean(independent, axis=0), empirical)) / 6 < 0.5


def test_clean_loops_close_and_broken_loops_are_seen():
    truth, views = corner_session(3, seed=23)
    members = true_members(truth)
    assert max(loop.mahalanobis for loop in loop_closures(views, members)) < CHI_6DOF_997

    def broken(shift_px: float) -> RigViews:
        rows = [list(r) for r in views.views]
        for row in rows:
            if row[2] is not None and row[1] is None:
                row[2] = type(row[2])(row[2].name, row[2].corner_ids, row[2].corners_px + [shift_px, 0.0])
        return RigViews(views.cameras, views.model_points_m, views.frames, tuple(tuple(r) for r in rows))

    d = {
        shift: max(loop.mahalanobis for loop in loop_closures(broken(shift), members)) for shift in (3.0, 1.0)
    }
    assert d[3.0] > CHI_6DOF_997 and d[1.0] > CHI_6DOF_997, d


def test_the_loop_closures_run_every_library_on_one_thread(monkeypatch) -> None:
    """The pair solves and loop covariances run one after another: spare BLAS threads would only spin (a
    4-camera rig's solve-folders spent 5-8 % more CPU at the same wall before this block,
    benchmarks/results/station.md)."""
    from threadpoolctl import threadpool_limits

    import calibctl.core.extrinsics.rig_validation as rig_validation
    from calibctl.core.blas_threads import thread_counts

    seen: list[dict[str, int]] = []
    real = rig_validation.pairwise_solutions

    def recording(*args, **kwargs):
        seen.append(thread_counts())
        return real(*args, **kwargs)

    monkeypatch.setattr(rig_validation, "pairwise_solutions", recording)
    truth, views = corner_session(3, seed=41)
    with threadpool_limits(limits=2):
        loop_closures(views, true_members(truth))
    assert seen and all(set(counts.values()) == {1} for counts in seen)
