"""Honesty of the scale-misalignment IMU model on renders: z = (estimate - truth) / one-sigma over seeds
for the 24 IMU states and the extrinsic (rotation x y z, translation x y z, td), and how often the
observability gate passes.

Each seed renders a 12 s one-camera dance (``core.synth.imu``; td from -10 to +14 ms) whose IMU has its
own scale, misalignment, gyro-to-accelerometer rotation and g-sensitivity drawn from the seed: every
scale, misalignment and rotation state N(0, 0.005), every g-sensitivity entry N(0, 2.5e-4) (a quarter of
the prior sigmas: data-sheet sizes). Solved as `imu solve --imu-model scale-misalignment` solves
(``calibrate``, the 10-block jackknife on, no k-fold). Prints the mean and sd of the z-scores per group;
asserts nothing.

    python benchmarks/bench_imu_model_honesty.py [--seeds 20] [--duration-s 12]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_imu_joint_honesty import summary, z_scores  # noqa: E402
from machine import cpu_model, load_1min  # noqa: E402

from calibctl.core.imu import intrinsics  # noqa: E402
from calibctl.core.imu.calibrate import calibrate  # noqa: E402
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples  # noqa: E402
from calibctl.core.imu.solve import SolveOptions  # noqa: E402
from calibctl.core.synth.imu import synthesize_imu_camera  # noqa: E402

GROUPS = {"M_gyro": slice(0, 6), "C_gyro_i": slice(6, 9), "M_accel": slice(9, 15), "A_gyro": slice(15, 24)}


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--duration-s", type=float, default=12.0)
    args = parser.parse_args()
    print(
        f"# {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} CPUs ({cpu_model()}), "
        f"load {load_1min():.1f}, {args.seeds} seeds of {args.duration_s:g} s"
    )
    z_imu, z_ext, passed = [], [], 0
    c0 = time.process_time()
    for seed in range(200, 200 + args.seeds):
        rng = np.random.default_rng(seed)
        x_true = np.r_[0.005 * rng.standard_normal(15), 2.5e-4 * rng.standard_normal(9)]
        rec = synthesize_imu_camera(
            seed,
            duration_s=args.duration_s,
            td_s=0.004 * (seed % 7) - 0.01,
            imu_scale_misalignment=intrinsics.matrices(x_true),
        )
        imu = ImuSamples(rec.imu_t_s, rec.gyro_rad_s, rec.accel_m_s2)
        lens = (rec.camera_matrix, rec.dist_coeffs, rec.image_size)
        frames = CameraFrames(rec.cam_t_s, rec.object_points, rec.image_points, *lens)
        noise = ImuNoise(rec.truth.gyro_noise_density, rec.truth.accel_noise_density, 1e-5, 1e-4)
        cal = calibrate(imu, frames, noise, SolveOptions(folds=0, imu_model="scale-misalignment"))
        s = cal.solution
        if s is None or s.imu_intrinsics is None:
            print(f"seed {seed}: no solution ({', '.join(g.gate for g in cal.failed)})")
            continue
        passed += cal.passed
        if not cal.passed:
            print(f"seed {seed}: refused by " + "; ".join(f"{g.gate} {g.value:.3g}" for g in cal.failed))
        m = s.imu_intrinsics
        z_imu.append((m.x - x_true) / m.sigma)
        z_ext.append(z_scores(s, rec.truth))
    zi, ze = np.array(z_imu), np.array(z_ext)
    print(f"gate passed on {passed} of {args.seeds}")
    for name, cols in GROUPS.items():
        print(f"{name:9s} z: {summary(zi[:, cols])}")
    print(f"extrinsic z (rot xyz, t xyz, td): {summary(ze)}")
    print(f"cpu {time.process_time() - c0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
