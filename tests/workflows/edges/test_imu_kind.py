"""The camera-IMU entry of the edge-kind table: its tree edge, lint rules and /tf_static export."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from calibctl.core.extrinsics import se3
from calibctl.errors import UsageError
from calibctl.workflows.edges.kinds import IMU, kind_of
from calibctl.workflows.edges.versions import edge_findings
from tests.artifacts.test_imu_contract import imu_estimate, imu_result
from tests.store.rig_documents import rig_calibration

T = se3.transform(se3.rotation_from_rotvec(np.array([0.1, -1.2, 0.3])), [0.02, -0.06, 0.01])


def _result(sigma_mm: float = 1.0, status: str = "accepted"):
    cov = np.diag([1e-8, 2e-8, 3e-8, 1e-6, 2e-6, 3e-6, 4e-8])
    est = imu_estimate(cov.tolist()).model_copy(
        update={"T_imu_cam": tuple(map(tuple, T.tolist())), "sigma_translation_mm": (sigma_mm, 1.0, 1.0)}
    )
    return imu_result(est).model_copy(update={"status": status})


def test_the_tree_edge_is_T_imu_cam_with_the_rotation_translation_block_of_the_covariance() -> None:
    ev = _result()
    assert kind_of(ev) is IMU
    edge = IMU.tree_edge(ev)
    assert (edge.parent, edge.child, edge.source) == ("imu", "CAM-0001", "camera-imu")
    assert np.allclose(edge.T_parent_child, T)
    assert edge.sigma_translation_mm > 0 and np.array(edge.covariance).shape == (6, 6)


def test_imu_lint_rules_gates_stale_member_and_loose_sigma() -> None:
    ev = _result()
    assert edge_findings([ev], {"CAM-0001": 1}) == []
    stale = edge_findings([ev], {"CAM-0001": 2})
    assert [f.rule for f in stale] == ["imu-stale-member"] and "CAM-0001@2" in stale[0].message
    loose = edge_findings([_result(sigma_mm=25.0)], {"CAM-0001": 1})
    assert [(f.rule, f.severity) for f in loose] == [("imu-uncertainty", "warning")]
    gate = ev.gates[0].model_copy(update={"passed": False, "hint": "turn about every axis"})
    failed = edge_findings([ev.model_copy(update={"gates": [gate]})], {"CAM-0001": 1})
    assert [(f.rule, f.fix) for f in failed] == [("imu-gates", "turn about every axis")]
    flat = ev.model_copy(
        update={"estimate": ev.estimate.model_copy(update={"covariance": np.zeros((7, 7)).tolist()})}
    )
    assert IMU.no_sigma(flat) is not None
    assert [f.rule for f in edge_findings([flat], {"CAM-0001": 1})] == ["imu-uncertainty"]


def test_the_tf_export_of_the_edge_and_a_rejected_one_refused() -> None:
    cal = rig_calibration()
    text = IMU.tf(_result(), cal, {"imu": "imu_link"})
    assert text.startswith("# calibctl imu imu -> CAM-0001 of rig")
    (t,) = yaml.safe_load(text)["transforms"]
    assert (t["header"]["frame_id"], t["child_frame_id"]) == ("imu_link", "CAM-0001")
    q = t["transform"]["rotation"]
    R = se3.rotation_from_quaternion(np.array([q["w"], q["x"], q["y"], q["z"]]))
    assert np.allclose(R, T[:3, :3]) and t["transform"]["translation"]["x"] == pytest.approx(0.02)
    with pytest.raises(UsageError, match="was rejected: no transform is published"):
        IMU.tf(_result(status="rejected"), cal, None)
