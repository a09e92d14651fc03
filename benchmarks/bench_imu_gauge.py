"""The camera-IMU solve's metric gauge on renders: a board registered at the wrong size and a camera held
with another lens' intrinsics, against the right ones, over seeds.

Each seed renders a 6 s dance (``core.synth.imu``, 50 mm-equivalent board, EuRoC-like lens) and calibrates
it three ways with ``core.imu.calibrate`` (no k-fold): as rendered; with the board's points at 0.8x (a
50 mm board registered at 40 mm); with fx and fy 6 % short (785 px held for an 835 px lens). Printed per
run: the verdict, the failed gates, the board scale +/- sigma (``board_scale``) and the camera fit's F
ratio and excess (``camera_fit``); then per case the refusals and, for the right data, the scale's z-scores.
EuRoC's figures come from ``bench_imu_euroc.py`` (its gate line prints both values).

Run: python benchmarks/bench_imu_gauge.py [--seeds 1-24] [--cases ok,board40,lens6]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from datetime import UTC, datetime

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model, load_1min  # noqa: E402

from calibctl.core.imu.calibrate import calibrate  # noqa: E402
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples  # noqa: E402
from calibctl.core.imu.solve import SolveOptions  # noqa: E402
from calibctl.core.synth.imu import synthesize_imu_camera  # noqa: E402

LENS = 785.0 / 835.0


def variant(frames: CameraFrames, case: str) -> tuple[CameraFrames, float]:
    """The frames as the case holds them and the registered square edge (mm) it names."""
    if case == "board40":
        return replace(frames, object_points=tuple(0.8 * p for p in frames.object_points)), 40.0
    if case == "lens6":
        K = frames.camera_matrix.copy()
        K[0, 0] *= LENS
        K[1, 1] *= LENS
        return replace(frames, camera_matrix=K), 50.0
    return frames, 50.0


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", default="1-24", help="first-last")
    parser.add_argument("--cases", default="ok,board40,lens6")
    args = parser.parse_args()
    first, last = (int(v) for v in args.seeds.split("-"))
    cases = args.cases.split(",")
    print(
        f"# {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} CPUs ({cpu_model()}), "
        f"load {load_1min():.1f}"
    )
    runs: dict[str, list[tuple[bool, float, float, float]]] = {c: [] for c in cases}
    for seed in range(first, last + 1):
        rec = synthesize_imu_camera(seed, motion="dance", duration_s=6.0)
        imu = ImuSamples(rec.imu_t_s, rec.gyro_rad_s, rec.accel_m_s2)
        frames = CameraFrames(
            rec.cam_t_s,
            rec.object_points,
            rec.image_points,
            rec.camera_matrix,
            rec.dist_coeffs,
            rec.image_size,
        )
        noise = ImuNoise(rec.truth.gyro_noise_density, rec.truth.accel_noise_density, 1e-5, 1e-4)
        for case in cases:
            held, square_mm = variant(frames, case)
            c0 = time.process_time()
            cal = calibrate(imu, held, noise, SolveOptions(folds=0), square_mm=square_mm)
            gate = {g.gate: g for g in cal.gates}
            scale, fit = gate["board_scale"], gate["camera_fit"]
            sigma = float(scale.detail["sigma"])
            runs[case].append((cal.passed, scale.value, sigma, fit.value))
            print(
                f"{case:8s} seed {seed:3d}: {'accepted' if cal.passed else 'REFUSED '} "
                f"{[g.gate for g in cal.failed]} scale {scale.value:.4f} +/- {sigma:.4f} F {fit.value:.2f} "
                f"excess {float(fit.detail['excess_px']):.3f} px "
                f"cpu {time.process_time() - c0:.1f} s",
                flush=True,
            )
    for case, rows in runs.items():
        passed, scale, sigma, f = (np.array(v) for v in zip(*rows, strict=True))
        z = (scale - 1.0) / sigma
        print(
            f"{case}: {int(np.sum(~passed.astype(bool)))} of {len(rows)} refused; scale "
            f"{scale.min():.4f}..{scale.max():.4f} (z mean {z.mean():+.2f} sd {z.std(ddof=1):.2f}); "
            f"F {f.min():.2f}..{f.max():.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
