"""Is T_lidar_cam's one-sigma honest? (error / sigma) over 120 seeded renders of 12 poses each.

Each render has its own true T, 10 mm range noise, a 5 mm bias per laser (fixed per session, as a
real unit's), 0.2 px corner noise and a post behind the board as clutter. Honest sigma: the z-scores
of each translation and rotation component have mean within +/-0.3 and standard deviation 0.7-1.4.

Why 120 seeds (docs/lidar.md "Honesty on renders"): the mean of one component over n seeds has a standard
error of ~1.1 / sqrt(n), and translation along LiDAR z and rotation about LiDAR y carry the extra spread of
the per-laser biases: an elevation trend across the lasers tilts every board about LiDAR y much as a pitch
of T does (the two differ only through the boards' 1/range), so the solve recovers ~60% of such a trend and
the rest moves t_z and rot_y. Over seeds 0-59 the drawn biases happen to share a trend (upper lasers
short, lower long) and those two means sit at -0.35 / -0.33; over seeds 60-119 at -0.04 / -0.02. At the
truth the board points and edges are unbiased (mean point-to-plane and edge residuals under 0.2 mm), so it
is the draw, not the estimator: 120 seeds bring the standard error to ~0.1 and all six are held to 0.3.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.extrinsics import se3
from calibctl.core.lidar import render
from calibctl.core.lidar import solve as ls
from calibctl.core.lidar.segment import segment_board

SEEDS = range(120)
POSES = 12


@pytest.mark.slow
def test_z_scores_over_120_seeds_have_unit_spread() -> None:
    zt, zr = [], []
    for seed in SEEDS:
        session = render.render_session(POSES, seed)
        poses = []
        for i, p in enumerate(session.poses):
            found = segment_board(p.cloud, session.box, session.board.backing_m)
            if found.accepted and p.camera is not None:
                poses.append(ls.Pose(str(i), p.camera, found))
        sol = ls.solve(poses, session.board)
        T = session.T_lidar_cam
        zt.append((sol.T_lidar_cam[:3, 3] - T[:3, 3]) / sol.sigma_translation_m)
        zr.append(
            se3.rotvec_from_rotation(sol.T_lidar_cam[:3, :3] @ T[:3, :3].T)
            / np.radians(sol.sigma_rotation_deg)
        )
    z = np.hstack([np.array(zt), np.array(zr)])  # t x y z, rotation about x y z
    assert np.all(np.abs(z.mean(axis=0)) < 0.3), z.mean(axis=0)
    assert np.all((z.std(axis=0) > 0.7) & (z.std(axis=0) < 1.4)), z.std(axis=0)


def test_the_truth_leaves_unbiased_board_points_and_edges() -> None:
    """The data the solve fits are unbiased at the true T, camera poses and laser biases: the half-step edge
    correction moves ring end points onto the outline on average, on the upper and the lower sides of the
    diamond alike, and the points sit on the plane (the render applies each laser's bias along its ray)."""
    plane, edge, upper = [], [], []
    for seed in range(3):
        session = render.render_session(12, seed)
        for p in session.poses:
            found = segment_board(p.cloud, session.box, session.board.backing_m)
            if not found.accepted or p.camera is None:
                continue
            T_cam_board = se3.invert(session.T_lidar_cam) @ p.T_lidar_board
            pr, er = ls.pose_residuals(
                session.T_lidar_cam,
                T_cam_board,
                ls.Pose("x", p.camera, found),
                session.board,
                0.0,
                -session.laser_bias_m,
            )
            plane.append(pr)
            edge.append(er)
            upper.append(found.edge_points_m[:, 2] > found.centre_m[2])
    e, up = np.concatenate(edge), np.concatenate(upper)
    # edge residuals scatter ~5 mm over ~800 end points: a 1 mm mean would be a biased outline
    assert abs(e.mean()) < 1e-3 and abs(e[up].mean()) < 1e-3 and abs(e[~up].mean()) < 1e-3, e.mean()
    assert abs(np.concatenate(plane).mean()) < 1e-3
