"""The issue's proof on rendered photos: calibctl's detector on ray-traced images of known rigs, the
members' true intrinsics held fixed (the renderer's camera), extrinsics solved."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_validation import loop_closures, validate_rig_holdout
from calibctl.core.extrinsics.se3 import rotation_angle_deg
from tests.core.rig_sessions import rendered_session, true_members

BASELINE_TOL_MM = 0.1
ROTATION_TOL_DEG = 0.05
RECTIFIED_MAX_RMS_PX = 0.1
CHI_6DOF_997 = 4.48

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def stereo_75mm():
    return rendered_session(2, seed=75, n_frames=14, baselines_m=(0.075,))


def test_a_75mm_stereo_pair_is_recovered(stereo_75mm):
    truth, views = stereo_75mm
    sol = solve_rig(views, true_members(truth))
    edge = sol.tree.edges[0]
    T_true = truth.T_root_cam[1]
    assert abs(edge.translation_mm - np.linalg.norm(T_true[:3, 3]) * 1e3) < BASELINE_TOL_MM
    assert rotation_angle_deg(edge.T_parent_child[:3, :3] @ T_true[:3, :3].T) < ROTATION_TOL_DEG
    assert edge.sigma_translation_mm < BASELINE_TOL_MM


def test_rectified_rows_agree_on_held_out_frames(stereo_75mm):
    truth, views = stereo_75mm
    pair = validate_rig_holdout(views, true_members(truth)).pairs[0]
    assert pair.rectified_rms_px < RECTIFIED_MAX_RMS_PX
    assert pair.epipolar_rms_px < RECTIFIED_MAX_RMS_PX


@pytest.mark.parametrize("n_cameras", [3, 4])
def test_rendered_rigs_close_their_loops(n_cameras):
    truth, views = rendered_session(n_cameras, seed=300 + n_cameras, n_frames=12, min_cameras=3)
    loops = loop_closures(views, true_members(truth))
    assert len(loops) >= (1 if n_cameras == 3 else 4)
    for loop in loops:
        assert loop.mahalanobis < CHI_6DOF_997, loop
