"""CPU time against wall time per solve stage: does a stage use more cores than its parallelism?

    PYTHONPATH=. .venv/bin/python benchmarks/bench_threads.py RENDERED_FOLDER RIG_FOLDER [--repeats 3]

RENDERED_FOLDER: ``calibctl synth OUT --views 96 --size 1280x960`` (its first 48 views are solved);
RIG_FOLDER: ``calibctl synth OUT --rig 4 --views 40 --size 1280x960`` (CAM0..CAM3). Corners are detected
once, on one thread, outside the timed stages. Stages, each timed in this process (wall by
perf_counter, CPU by resource.getrusage(RUSAGE_SELF): every thread of the process):
  * solve_intrinsics, 48 views, k1k2 with its covariance;
  * validate_holdout, 48 views (its own 2 fold threads);
  * solve_rig_folders on the 4-camera rig, detection on one worker (member solves, the joint LM,
    held-out pairs, loops).
Run it against another checkout (PYTHONPATH=/work/main) for the before; it only calls APIs both have.
Prints a markdown table with machine, date and load.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import resource
import sys
import time
from pathlib import Path

import cv2
from machine import cpu_model  # benchmarks/machine.py (scripts run from benchmarks/)

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.camera_split import forget_recent_checks
from calibctl.core.capture.image_outcomes import classify_session, list_images
from calibctl.core.intrinsics.solve import forget_recent_solves, solve_intrinsics
from calibctl.core.intrinsics.validation import validate_holdout
from calibctl.workflows.rig.rig_folders import solve_rig_folders

BOARD = BoardSpec.chessboard(9, 6, 0.025)
N_VIEWS = 48


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def timed(fn, repeats: int) -> tuple[float, float]:
    """(best wall s, CPU s of that run)."""
    best = (float("inf"), 0.0)
    for _ in range(repeats):
        forget_recent_solves()  # every round computes: a remembered solve or check would time a digest
        forget_recent_checks()
        c, t = cpu_s(), time.perf_counter()
        fn()
        wall, cpu = time.perf_counter() - t, cpu_s() - c
        best = min(best, (wall, cpu))
    return best


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rendered", type=Path)
    parser.add_argument("rig", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    outcomes = [o for o in classify_session(list_images(args.rendered), BOARD, workers=1) if o.accepted][
        :N_VIEWS
    ]
    obj = [BOARD.object_points()[o.corner_ids] for o in outcomes]
    img = [o.corners_px for o in outcomes]
    size = outcomes[0].image_size
    fit = solve_intrinsics(obj, img, size, "k1k2")
    cams = sorted(p for p in args.rig.iterdir() if p.is_dir())
    stages = [
        (f"solve_intrinsics, {len(obj)} views", lambda: solve_intrinsics(obj, img, size, "k1k2"), 1),
        (f"validate_holdout, {len(obj)} views", lambda: validate_holdout(obj, img, size, "k1k2", fit=fit), 2),
        (
            f"solve_rig_folders, {len(cams)} cameras (detection on 1 worker)",
            lambda: solve_rig_folders({p.name: p for p in cams}, BOARD, workers=1),
            1,
        ),
    ]
    load = os.getloadavg()
    print(
        f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {os.cpu_count()} CPUs "
        f"({len(os.sched_getaffinity(0))} available), Python {platform.python_version()}, OpenCV "
        f"{cv2.__version__}, "
        f"load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} at start; code from "
        f"{Path(sys.modules['calibctl'].__file__).parent.parent}\n"
    )
    print("| stage | parallelism used | wall s (best) | CPU s | CPU / wall |\n|---|---|---|---|---|")
    for name, fn, parallel in stages:
        wall, cpu = timed(fn, args.repeats)
        print(f"| {name} | {parallel} | {wall:.3f} | {cpu:.3f} | {cpu / wall:.2f} |", flush=True)
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
