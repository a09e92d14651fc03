"""The rig's frame-level (cluster-robust) sigma: on per-corner noise it leaves the Jacobian sigma honest, and
where every frame carries its own error (a sync slip shifting one camera's corners) it reports the larger
sigma that the spread of the baseline over seeded sessions asks for."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_tree import sigma_translation_mm
from calibctl.core.extrinsics.rig_uncertainty import MIN_FRAMES
from tests.core.rig_sessions import corner_session, true_members

N_SESSIONS = 30
FRAME_SHIFT_PX = 1.0  # sd of one camera's per-frame shift: a board that moved between the two exposures


def _shifted(views: RigViews, rng: np.random.Generator) -> RigViews:
    rows = []
    for row in views.views:
        shift = rng.normal(0.0, FRAME_SHIFT_PX, 2)
        v = row[1]
        rows.append(
            (row[0], BoardView(v.name, v.corner_ids, v.corners_px + shift) if v is not None else None)
        )
    return RigViews(views.cameras, views.model_points_m, views.frames, tuple(rows))


def _z(frame_error: bool) -> tuple[np.ndarray, np.ndarray]:
    z, z_jac = [], []
    for seed in range(N_SESSIONS):
        truth, views = corner_session(2, seed=4000 + seed, baselines_m=(0.075,), n_frames=15)
        if frame_error:
            views = _shifted(views, np.random.default_rng(seed))
        sol = solve_rig(views, true_members(truth))
        T = sol.T_a_b(1, 0)
        err = np.linalg.norm(T[:3, 3]) * 1e3 - np.linalg.norm(truth.T_root_cam[1][:3, 3]) * 1e3
        z.append(err / sigma_translation_mm(sol.pair_covariance(1, 0), T[:3, 3]))
        z_jac.append(err / sigma_translation_mm(sol.pair_covariance(1, 0, jacobian=True), T[:3, 3]))
    return np.array(z), np.array(z_jac)


def test_per_corner_noise_keeps_the_sigma_honest():
    z, z_jac = _z(frame_error=False)
    assert 0.8 < z.std(ddof=1) < 1.3, z
    assert 0.8 < z_jac.std(ddof=1) < 1.5, z_jac


def test_a_per_frame_error_is_carried_by_the_frame_level_sigma():
    z, z_jac = _z(frame_error=True)
    assert z_jac.std(ddof=1) > 1.5, z_jac  # the Jacobian does not see errors shared by a frame's corners
    assert 0.7 < z.std(ddof=1) < 1.3, z


def test_the_reported_sigma_is_the_larger_per_parameter():
    truth, views = corner_session(2, seed=4100, baselines_m=(0.075,), n_frames=15)
    sol = solve_rig(_shifted(views, np.random.default_rng(0)), true_members(truth))
    assert sol.frame_factors is not None and sol.frame_clusters == 15
    jac, rep = np.diag(sol.jacobian_covariance), np.diag(sol.covariance)
    assert np.all(rep >= jac * (1 - 1e-9))
    np.testing.assert_allclose(np.sqrt(rep / jac), np.maximum(1.0, sol.frame_factors), rtol=1e-9)
    assert sol.frame_factors.max() > 1.5


def test_too_few_frames_report_the_jacobian_sigma():
    truth, views = corner_session(2, seed=4200, baselines_m=(0.075,), n_frames=MIN_FRAMES - 1)
    sol = solve_rig(views, true_members(truth))
    assert sol.frame_factors is None
    np.testing.assert_array_equal(sol.covariance, sol.jacobian_covariance)


@pytest.mark.parametrize("n_extra", [0, 3])
def test_member_photos_the_rig_does_not_use_are_clusters_too(n_extra):
    truth, views = corner_session(2, seed=4300, baselines_m=(0.075,), n_frames=12)
    members = []
    for c, m in enumerate(true_members(truth)):
        p = m.n_params
        pulls = {row[c].name: np.full(p, 1e-3) for row in views.views if row[c] is not None}
        pulls.update({f"only-{c}-{i}": np.full(p, 1e-3) for i in range(n_extra)})
        members.append(
            MemberIntrinsics(
                m.name,
                m.camera_matrix,
                m.dist_coeffs,
                m.image_size,
                covariance=np.eye(p) * 1e-6,
                view_influences=pulls,
            )
        )
    # view names are per frame ("f0".."f11") and shared by both cameras, as the rig's frames pair them
    sol = solve_rig(views, members)
    assert sol.frame_clusters == len(views.frames) + 2 * n_extra
