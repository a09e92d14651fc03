"""core.compare.rig_diff: the change of each camera pair between two rig versions, its sigma, the depth
error."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibctl.core.compare.rig_diff import camera_pairs, pair_changes
from calibctl.core.extrinsics.rig_tree import Edge, RigTree

SIGMA_ROT_RAD = 1e-4  # 0.0057 deg
SIGMA_T_M = 3e-5  # 0.03 mm
COV = np.diag([SIGMA_ROT_RAD**2] * 3 + [SIGMA_T_M**2] * 3)


def _tree(baseline_m: float = 0.075, yaw_rad: float = 0.0, third: bool = False) -> RigTree:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.array([0.0, yaw_rad, 0.0]))[0]
    T[0, 3] = baseline_m
    edges = [Edge("L", "R", T, COV)]
    if third:
        T3 = np.eye(4)
        T3[1, 3] = 0.05
        edges.append(Edge("L", "C", T3, COV))
    return RigTree("L", tuple(edges))


def test_an_unchanged_rig_has_no_change_and_no_flag() -> None:
    (pair,) = pair_changes(_tree(), _tree(), [("L", "R")])
    assert pair.a == "L" and pair.b == "R" and not pair.significant
    assert pair.chi2 == pytest.approx(0.0, abs=1e-9) and pair.baseline_change_mm == pytest.approx(
        0.0, abs=1e-9
    )
    assert pair.sigma_baseline_change_mm == pytest.approx(
        np.sqrt(2) * 0.03, rel=1e-3
    )  # two independent solves
    assert all(abs(d.error_m) < 1e-9 for d in pair.depth)


def test_a_longer_baseline_is_flagged_and_scales_depth() -> None:
    (pair,) = pair_changes(_tree(0.075), _tree(0.076), [("L", "R")])
    assert pair.significant and pair.baseline_change_mm == pytest.approx(1.0, rel=1e-6)
    assert pair.baseline_change_mm / pair.sigma_baseline_change_mm > 20
    by_depth = {d.depth_m: d for d in pair.depth}
    # A's 75 mm triangulates B's 76 mm rig short by Z / 76: dZ/Z = -1/76 at every depth
    for z in (1.0, 2.0, 5.0, 10.0):
        assert by_depth[z].error_m == pytest.approx(-z / 76.0, rel=1e-6)


def test_a_yaw_change_grows_depth_error_with_the_square_of_depth() -> None:
    (pair,) = pair_changes(_tree(yaw_rad=0.0), _tree(yaw_rad=1e-3), [("L", "R")])
    assert pair.significant and pair.rotation_deg == pytest.approx(np.rad2deg(1e-3), rel=1e-6)
    e1, e10 = pair.depth[0].error_m, pair.depth[-1].error_m
    assert abs(e10) > 50 * abs(e1)  # ~ Z^2 dtheta / B: 100x from 1 m to 10 m, less the dtheta Z / B term
    assert abs(e1) == pytest.approx(1.0**2 * 1e-3 / 0.075, rel=0.1)
    assert pair.depth[-1].sigma_m > pair.depth[0].sigma_m > 0


def test_every_pair_through_the_tree_is_compared() -> None:
    a, b = _tree(third=True), _tree(0.076, third=True)
    pairs = pair_changes(a, b, camera_pairs(a, b, ["L", "R", "C", "absent"]), no_depth=[("L", "C")])
    assert [(p.a, p.b) for p in pairs] == [("L", "R"), ("L", "C"), ("R", "C")]
    flagged = {(p.a, p.b): p.significant for p in pairs}
    assert flagged == {("L", "R"): True, ("L", "C"): False, ("R", "C"): True}
    assert pairs[1].depth == () and len(pairs[0].depth) == 4
