"""Camera-LiDAR: segmentation of one sweep and the solve of 20 poses, beside a plain numpy script.

calibctl: core.lidar.segment.segment_board (box, RANSAC, least squares, ring runs, outline, dimension
error) and core.lidar.solve.solve (closed form, joint least squares with the camera poses and per-laser
biases, covariance). Plain: the box crop, a numpy RANSAC of the same iterations and an SVD refit (no
outline, no outcome), and the closed form alone (Kabsch on normals + least squares on distances, no
covariance). Data: the 20 acfr VLP-16 sweeps (~24k points each) and their images; a rendered 30k-point
sweep. Prints markdown; asserts nothing.

    .venv/bin/python benchmarks/bench_lidar.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibctl.core.lidar import render  # noqa: E402
from calibctl.core.lidar import solve as ls  # noqa: E402
from calibctl.core.lidar.segment import StationBox, segment_board  # noqa: E402
from calibctl.core.lidar.target import BackingBoard  # noqa: E402
from calibctl.workflows.lidar import lidar_solve as wf  # noqa: E402
from calibctl.workflows.lidar.scans import read_scan  # noqa: E402

ACFR = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "acfr-lidar-camera"
if not ACFR.is_dir():
    ACFR = Path("/work/shared/datasets/acfr-lidar-camera")
BOX = StationBox((1.0, -2.2, -0.8), (3.6, 1.6, 0.6))
BOARD = BackingBoard(5, 7, 0.095, (0.61, 0.85), (0.002, 0.0))


def plain_segment(points: np.ndarray, box: StationBox, rng: np.random.Generator) -> np.ndarray:
    """Crop, RANSAC (300 tries, 3 cm), SVD refit: the script a user would write first."""
    p = points[box.contains(points)]
    best = np.zeros(len(p), bool)
    for _ in range(300):
        a, b, c = p[rng.integers(0, len(p), 3)]
        n = np.cross(b - a, c - a)
        if np.linalg.norm(n) < 1e-9:
            continue
        n /= np.linalg.norm(n)
        inl = np.abs((p - a) @ n) < 0.03
        if inl.sum() > best.sum():
            best = inl
    q = p[best]
    return np.linalg.svd(q - q.mean(axis=0))[2][2]


def timed(fn, repeats: int) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        runs.append(time.process_time() - t0)
    return statistics.median(runs)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    sweeps = [read_scan(p) for p in sorted((ACFR / "pcd").glob("*_full.pcd"))]
    synth = render.render_session(1, seed=0, azimuth_step_deg=0.19).poses[0].cloud
    print(
        f"## camera-LiDAR (median CPU s of {args.repeats}; {len(sweeps)} acfr sweeps, "
        f"{int(np.mean([len(s.points_m) for s in sweeps]))} points on average; rendered sweep "
        f"{len(synth.points_m)} points)\n"
    )
    print("| step | calibctl | plain numpy |\n|---|---|---|")
    ours = timed(lambda: [segment_board(s, BOX, BOARD.backing_m) for s in sweeps], args.repeats) / len(sweeps)
    plain = timed(
        lambda: [plain_segment(s.points_m, BOX, np.random.default_rng(0)) for s in sweeps], args.repeats
    ) / len(sweeps)
    print(f"| segmentation, one acfr sweep | {ours * 1e3:.1f} ms | {plain * 1e3:.1f} ms |")
    ours = timed(lambda: segment_board(synth, render.RENDER_BOX, BOARD.backing_m), args.repeats)
    plain = timed(
        lambda: plain_segment(synth.points_m, render.RENDER_BOX, np.random.default_rng(0)), args.repeats
    )
    print(
        f"| segmentation, rendered {len(synth.points_m)}-point sweep | {ours * 1e3:.1f} ms | "
        f"{plain * 1e3:.1f} ms |"
    )
    req = wf.LidarRequest(
        ACFR / "images", ACFR / "pcd", BOARD, BOX, ACFR / "camera_info.yaml", scan_pattern="*_full.pcd"
    )
    poses, _ = wf.collect_poses(req, wf.load_lens(None, req.camera_info, None))  # type: ignore[arg-type]
    ours = timed(lambda: ls.solve(poses, BOARD), args.repeats)
    plain = timed(lambda: ls.closed_form(poses, BOARD), args.repeats)
    print(
        f"| solve of {len(poses)} acfr poses (calibctl: joint LS + covariance; plain: closed form only) | "
        f"{ours:.2f} s | {plain * 1e3:.1f} ms |"
    )


if __name__ == "__main__":
    main()
