"""orient_tree: edges measured in any direction become one tree; loops and islands are refused;
the SE(3) helpers the rig and hand-eye modules share live in se3."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.rig_tree import Edge, T_to_pose, inverted, orient_tree

RNG = np.random.default_rng(7)


def _edge(parent: str, child: str) -> Edge:
    T = se3.transform(se3.random_rotation(RNG, 0.7), RNG.normal(size=3) * 0.1)
    A = RNG.normal(size=(6, 6)) * 1e-3
    return Edge(parent, child, T, A @ A.T)


CAM = _edge("cam0", "cam1")
FLANGE = _edge("flange", "cam0")
IMU = _edge("imu", "cam1")


def test_the_only_frame_without_a_parent_roots_the_tree():
    tree = orient_tree([CAM, FLANGE], "cam0")
    assert tree.root == "flange" and [(e.parent, e.child) for e in tree.edges] == [
        ("flange", "cam0"),
        ("cam0", "cam1"),
    ]
    assert np.allclose(tree.T("flange", "cam1"), FLANGE.T_parent_child @ CAM.T_parent_child)


def test_an_edge_met_from_its_child_is_inverted_with_its_covariance():
    tree = orient_tree([CAM, IMU], "cam0")
    assert tree.root == "cam0" and ("cam1", "imu") in [(e.parent, e.child) for e in tree.edges]
    assert np.allclose(tree.T("cam1", "imu"), se3.invert(IMU.T_parent_child), atol=1e-12)
    back = inverted(inverted(IMU))
    assert np.allclose(back.T_parent_child, IMU.T_parent_child, atol=1e-12)
    assert np.allclose(back.covariance, IMU.covariance, rtol=1e-5, atol=1e-12)
    # translation of the inverse is -R^T t: its covariance is not the original's
    assert not np.allclose(inverted(IMU).covariance, IMU.covariance)


def test_loops_and_islands_are_refused():
    with pytest.raises(ValueError, match="closes a loop"):
        orient_tree([CAM, IMU, _edge("imu", "cam0")], "cam0")
    with pytest.raises(ValueError, match="does not connect to cam0"):
        orient_tree([CAM, _edge("imu", "lidar")], "cam0")


def test_se3_helpers_agree_with_their_definitions():
    R = se3.rotation_from_rotvec([0.0, 0.0, np.radians(30.0)])
    assert se3.rotation_angle_deg(R) == pytest.approx(30.0, abs=1e-9)
    assert se3.rotation_angle_deg(se3.rotation_from_rotvec([1e-7, 0.0, 0.0])) == pytest.approx(
        np.degrees(1e-7), rel=1e-6
    )
    x, y, z, w = se3.quaternion_xyzw(R)
    assert (
        (x, y) == (0.0, 0.0)
        and z == pytest.approx(np.sin(np.radians(15.0)))
        and w == pytest.approx(np.cos(np.radians(15.0)))
    )
    assert np.allclose(T_to_pose(se3.invert(se3.transform(R, [1.0, 2.0, 3.0])))[3:], -R.T @ [1.0, 2.0, 3.0])
