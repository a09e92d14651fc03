"""T_lidar_cam on renders with known truth: recovered within its sigma, gates refuse what cannot be solved."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.extrinsics import se3
from calibctl.core.lidar import gates, render, validation
from calibctl.core.lidar import solve as ls
from calibctl.core.lidar.segment import segment_board

Z_LIMIT = 4.0  # one seed: |error| / sigma beyond this would be a 1-in-10^4 event for an honest sigma


def poses_of(session: render.RenderedSession) -> list[ls.Pose]:
    out = []
    for i, p in enumerate(session.poses):
        found = segment_board(p.cloud, session.box, session.board.backing_m)
        if found.accepted and p.camera is not None:
            out.append(ls.Pose(str(i), p.camera, found))
    return out


def test_rpy_matches_acfr_order() -> None:
    R = validation.rotation_from_rpy(-1.6954, -0.0209, -1.4929)
    np.testing.assert_allclose(validation.rpy_from_rotation(R), (-1.6954, -0.0209, -1.4929), atol=1e-12)
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_allclose(validation.rotation_from_rpy(0, 0, np.pi / 2), Rz, atol=1e-12)


def test_closed_form_and_joint_solve_recover_T_within_sigma() -> None:
    session = render.render_session(7, seed=11)
    poses = poses_of(session)
    assert len(poses) >= 6
    closed = ls.closed_form(poses, session.board)
    assert np.linalg.norm(closed[:3, 3] - session.T_lidar_cam[:3, 3]) < 0.05
    sol = ls.solve(poses, session.board)
    dt = sol.T_lidar_cam[:3, 3] - session.T_lidar_cam[:3, 3]
    dr = se3.rotvec_from_rotation(sol.T_lidar_cam[:3, :3] @ session.T_lidar_cam[:3, :3].T)
    assert np.all(np.abs(dt / sol.sigma_translation_m) < Z_LIMIT), (dt, sol.sigma_translation_m)
    assert np.all(np.abs(dr / np.radians(sol.sigma_rotation_deg)) < Z_LIMIT)
    assert np.all(sol.sigma_translation_m < 0.01) and sol.plane_rms_m < 0.02
    gate = gates.plane_rms_gate(sol.plane_rms_m * 1e3)
    assert gate.passed


@pytest.mark.slow
def test_a_30mm_range_offset_is_found() -> None:
    session = render.render_session(12, seed=5, range_offset_m=0.03)
    sol = ls.solve(poses_of(session), session.board, estimate_range_offset=True)
    assert sol.range_offset_sigma_m is not None and sol.range_offset_sigma_m < 0.01
    assert abs(sol.range_offset_m - 0.03) < 3 * sol.range_offset_sigma_m + 0.002, (
        sol.range_offset_m,
        sol.range_offset_sigma_m,
    )


def test_boards_all_facing_one_way_are_refused_naming_the_direction() -> None:
    session = render.render_session(8, seed=2, one_way=True)
    poses = poses_of(session)
    gate = gates.observability_gate(np.array([p.lidar.normal for p in poses]))
    assert not gate.passed and gate.reason == "unobservable"
    assert "unobservable" in gate.message and "LiDAR" in gate.message
    assert gate.hint is not None and "tilt the board" in gate.hint
    varied = poses_of(render.render_session(8, seed=2))
    assert gates.observability_gate(np.array([p.lidar.normal for p in varied])).passed


@pytest.mark.parametrize(
    ("gate", "ok"),
    [
        (gates.pose_count_gate(3, 10), False),
        (gates.pose_count_gate(6, 10), True),
        (gates.range_spread_gate([2.0, 2.1, 2.2]), False),
        (gates.range_spread_gate([1.5, 3.0]), True),
        (gates.dimension_gate(np.array([[40.0, 0.0]])), False),
        (gates.held_out_gate(30.0, 10.0), False),
    ],
)
def test_each_gate_can_fail_and_says_what_to_do(gate, ok: bool) -> None:
    assert gate.passed is ok
    if not ok:
        assert gate.hint and gate.reason
