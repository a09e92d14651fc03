"""Camera-LiDAR one-sigma honesty on renders: z = (estimate - truth) / one-sigma per component over seeds.

The setup of tests/core/lidar/test_render_honesty.py (12 poses per seed, 10 mm range noise, 5 mm bias per
laser, 0.2 px corners, the clutter post); ``--biases removed`` takes each laser's true bias out of the
sweep along its rays before segmentation, ``--biases negated`` flips its sign (the same poses and noise
either way). Prints the mean and sd of the six z-scores and the mean error in mm / mdeg; asserts nothing.

    python benchmarks/bench_lidar_honesty.py [--seeds 0-119] [--biases as-drawn|removed|negated]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibctl.core.extrinsics import se3  # noqa: E402
from calibctl.core.lidar import render  # noqa: E402
from calibctl.core.lidar import solve as ls  # noqa: E402
from calibctl.core.lidar.pcd import PointCloud  # noqa: E402
from calibctl.core.lidar.segment import segment_board  # noqa: E402

POSES = 12
LASER_BIAS_M = 0.005


def z_scores(seed: int, biases: str) -> tuple[np.ndarray, np.ndarray]:
    """(6,) z-scores (translation x y z, rotation about LiDAR x y z) and (6,) errors (mm, mdeg)."""
    session = render.render_session(POSES, seed, laser_bias_m=LASER_BIAS_M)
    bias = session.laser_bias_m
    poses = []
    for i, p in enumerate(session.poses):
        cloud = p.cloud
        if biases != "as-drawn":  # the render added bias[ring] to each range: take it out once, or twice
            unit = cloud.points_m / np.linalg.norm(cloud.points_m, axis=1, keepdims=True)
            times = 1.0 if biases == "removed" else 2.0
            cloud = PointCloud(
                cloud.points_m - times * bias[cloud.ring][:, None] * unit, cloud.intensity, cloud.ring
            )
        found = segment_board(cloud, session.box, session.board.backing_m)
        if found.accepted and p.camera is not None:
            poses.append(ls.Pose(str(i), p.camera, found))
    sol = ls.solve(poses, session.board)
    T = session.T_lidar_cam
    et = sol.T_lidar_cam[:3, 3] - T[:3, 3]
    er = se3.rotvec_from_rotation(sol.T_lidar_cam[:3, :3] @ T[:3, :3].T)
    z = np.concatenate([et / sol.sigma_translation_m, er / np.radians(sol.sigma_rotation_deg)])
    return z, np.concatenate([et * 1e3, np.degrees(er) * 1e3])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-119", help="FIRST-LAST, inclusive")
    ap.add_argument(
        "--biases",
        choices=("as-drawn", "removed", "negated"),
        default="as-drawn",
        help="the render's per-laser biases as drawn, taken out of the sweep, or negated",
    )
    args = ap.parse_args()
    first, last = (int(v) for v in args.seeds.split("-"))
    rows = [z_scores(seed, args.biases) for seed in range(first, last + 1)]
    z = np.array([r[0] for r in rows])
    err = np.array([r[1] for r in rows])
    print(f"seeds {first}-{last}, per-laser biases {args.biases}")
    print("| | t x | t y | t z | rot x | rot y | rot z |\n|---|---|---|---|---|---|---|")
    print("| z mean | " + " | ".join(f"{v:+.2f}" for v in z.mean(axis=0)) + " |")
    print("| z sd | " + " | ".join(f"{v:.2f}" for v in z.std(axis=0)) + " |")
    print("| mean error (mm, mdeg) | " + " | ".join(f"{v:+.2f}" for v in err.mean(axis=0)) + " |")


if __name__ == "__main__":
    main()
