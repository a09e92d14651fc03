"""The LiDAR edge's evidence keeps the solve's full precision; only the printed JSON is rounded."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibctl.core.gate import GateResult
from calibctl.core.lidar.segment import StationBox
from calibctl.core.lidar.target import BackingBoard
from calibctl.workflows.lidar import lidar_solve as wf
from calibctl.workflows.lidar.rig_lidar import evidence

X_M = 0.1234567890123  # rounding to 9 digits would change it
GATE_VALUE = 0.123456789  # rounding to 4 digits would change it


def _outcome() -> wf.LidarOutcome:
    T = np.eye(4)
    T[:3, 3] = (X_M, -0.2, 0.3)
    cov = np.diag([1.1e-6, 2e-6, 3e-6, 4e-6, 5e-6, 6.123456789e-6])
    fit = wf.LidarFit(T, cov, (1.23456789, 2.0, 3.0), (0.0123456789, 0.02, 0.03))
    gate = GateResult("lidar-plane-rms", True, GATE_VALUE, 20.0, "fits")
    row = wf.ScanRow(1, "1.png", "1.pcd", "dimension_mismatch", "too wide")
    return wf.LidarOutcome("images", "scans", "CAM0@1", "pinhole", 0.0, [row], [gate], fit)


def test_the_lidar_evidence_keeps_full_precision_and_the_json_keeps_its_rounded_shape() -> None:
    outcome = _outcome()
    req = wf.LidarRequest(
        Path("images"),
        Path("scans"),
        BackingBoard(5, 7, 0.095, (0.61, 0.85)),
        StationBox((0, 0, 0), (1, 1, 1)),
    )
    ev = evidence(outcome, req, "lidar", "CAM0", "L5@1")
    assert ev.status == "accepted" and ev.transform is not None
    assert ev.transform.T_lidar_cam[0][3] == X_M
    assert ev.transform.sigma_translation_mm[0] == 1.23456789
    assert ev.transform.sigma_rotation_deg[0] == 0.0123456789
    assert ev.transform.covariance[5][5] == 6.123456789e-6
    assert ev.gates[0].value == GATE_VALUE
    doc = wf.result_json(outcome)
    assert doc["transform"]["matrix"][0][3] == round(X_M, 9) != X_M
    assert doc["gates"][0]["value"] == round(GATE_VALUE, 4)
    assert list(doc) == [
        "images", "scans", "lens", "lens_model", "range_offset_applied_mm", "outcomes", "transform",
        "outcome_counts", "status", "gates", "notes",
    ]  # fmt: skip
