"""Camera-IMU joint solve honesty on renders: two cameras of a rig against one IMU, z = (estimate - truth)
/ one-sigma per component over seeds, with each camera's T_imu_cam estimated, and with the second camera
held through the true rig pose.

The renders of tests/core/imu/test_zscores.py (4 s dances, td from -10 to +14 ms) with a second camera
11 cm along the first camera's x (``core.synth.imu.EUROC_LIKE_T_CAM0_CAM1``). Both cameras' z rows are
pooled (they share the trajectory, so they are not independent). Prints the mean and sd of the seven
z-scores (rotation x y z, translation x y z, td); asserts nothing. ``--bias-walk``: the biases solved as
random walks (``SolveOptions.bias_walk``; the renders' biases are constant, the noise file's walks small).

    python benchmarks/bench_imu_joint_honesty.py [--seeds 30] [--bias-walk]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model, load_1min  # noqa: E402

from calibctl.core.extrinsics import se3  # noqa: E402
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples  # noqa: E402
from calibctl.core.imu.solve import ImuCameraSolution, SolveOptions, solve_imu_cameras  # noqa: E402
from calibctl.core.synth.imu import (  # noqa: E402
    EUROC_LIKE_T_CAM0_CAM1,
    EUROC_LIKE_T_IMU_CAM,
    ImuCameraTruth,
    synthesize_imu_camera,
)


def z_scores(s: ImuCameraSolution, truth: ImuCameraTruth) -> np.ndarray:
    d_rot = se3.rotvec_from_rotation(s.T_imu_cam[:3, :3] @ truth.T_imu_cam[:3, :3].T)
    err = np.r_[d_rot, s.T_imu_cam[:3, 3] - truth.T_imu_cam[:3, 3], s.td_s - truth.td_s]
    return err / np.sqrt(np.diag(s.covariance_7))


def summary(z: np.ndarray) -> str:
    """Per-column mean and sd of (rows, k) z-scores, and the largest |z|."""
    return (
        f"mean {np.round(z.mean(axis=0), 2)}, sd {np.round(z.std(axis=0, ddof=1), 2)}, "
        f"largest |z| {np.abs(z).max():.2f}"
    )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--bias-walk", action="store_true", help="the biases as random walks")
    args = parser.parse_args()
    print(
        f"# {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} CPUs ({cpu_model()}), "
        f"load {load_1min():.1f}, bias_walk {args.bias_walk}"
    )
    options = SolveOptions(folds=0, bias_walk=args.bias_walk)
    T1 = EUROC_LIKE_T_IMU_CAM @ EUROC_LIKE_T_CAM0_CAM1
    z: dict[str, list[np.ndarray]] = {"joint": [], "held by the rig": []}
    c0 = time.process_time()
    for seed in range(100, 100 + args.seeds):
        rec = synthesize_imu_camera(seed, duration_s=4.0, td_s=0.004 * (seed % 7) - 0.01, more_cameras=(T1,))
        imu = ImuSamples(rec.imu_t_s, rec.gyro_rad_s, rec.accel_m_s2)
        cams = [
            CameraFrames(rec.cam_t_s, o, i, rec.camera_matrix, rec.dist_coeffs, rec.image_size)
            for o, i in (
                (rec.object_points, rec.image_points),
                (rec.more_cameras[0].object_points, rec.more_cameras[0].image_points),
            )
        ]
        noise = ImuNoise(rec.truth.gyro_noise_density, rec.truth.accel_noise_density, 1e-5, 1e-4)
        truths = (rec.truth, replace(rec.truth, T_imu_cam=T1))
        for name, rig in (("joint", None), ("held by the rig", [None, EUROC_LIKE_T_CAM0_CAM1])):
            sols = solve_imu_cameras(imu, cams, noise, options, rig=rig)
            z[name] += [z_scores(s, t) for s, t in zip(sols, truths, strict=True)]
    for name, rows in z.items():
        print(f"{name}: {len(rows)} rows, {summary(np.array(rows))}")
    print(f"cpu {time.process_time() - c0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
