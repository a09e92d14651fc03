"""Remap time per frame with the maps `calibctl export --format lut` writes, against computing the map
each frame.

    .venv/bin/python benchmarks/bench_lut.py [--repeats 50] [--sizes 640x480 1280x960]

For each size a k1k2p1p2k3 lens (fx = 0.8 w, the seed's 1280x960 drill scaled) is exported as a LUT the
way `calibctl export --format lut` builds it (workflows.exports.lut: alpha 0, R = I), the .npy files
written to a temporary folder and loaded back with np.load, then per frame (cv2.INTER_LINEAR, a grey and a
BGR uint8 frame):

- ``fixed``: cv2.remap with the CV_16SC2 + CV_16UC1 pair;
- ``float``: cv2.remap with the two CV_32FC1 maps;
- ``map each frame``: cv2.initUndistortRectifyMap (CV_16SC2) + cv2.remap, what a loop that keeps no LUT pays
  (cv2.undistort does the same inside, in row blocks: its time is listed too).

Each is timed ``--repeats`` times (after 3 warm-ups): best and median wall ms and best CPU ms, with
OpenCV's default threads and with cv2.setNumThreads(1) (a robot's pinned core). Also the maps' bytes in
memory and the np.load time of the four files. Nothing is asserted; the machine is shared, so the load
average is printed.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from machine import cpu_model, load_1min

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibctl.workflows.exports import lut  # noqa: E402


def _time(fn, repeats: int) -> str:
    """'best / median wall ms (best CPU ms)': under load the wall waits for a core, the CPU time does not."""
    for _ in range(3):
        fn()
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        fn()
        wall.append((time.perf_counter() - start) * 1e3)
        cpu.append((time.process_time() - start_cpu) * 1e3)
    return f"{min(wall):.2f} / {statistics.median(wall):.2f} ({min(cpu):.2f})"


def _camera(w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    K = np.array([[0.8 * w, 0.0, w / 2 + 3.1], [0.0, 0.8 * w, h / 2 - 2.4], [0.0, 0.0, 1.0]])
    return K, np.array([-0.28, 0.09, 0.0008, -0.0005, -0.012])


def run(size: tuple[int, int], repeats: int, threads: int) -> list[str]:
    w, h = size
    K, D = _camera(w, h)
    cam = lut.single_camera("BENCH", 1, "0" * 64, "bench", "pinhole", K, D, size, 0.0)
    payloads, entries = lut.build([cam])
    with tempfile.TemporaryDirectory() as tmp:
        for name, data in payloads.items():
            (Path(tmp) / name).write_bytes(data)
        start = time.perf_counter()
        maps = {f["map"]: np.load(Path(tmp) / f["path"]) for f in entries[0]["maps"]}
        load_ms = (time.perf_counter() - start) * 1e3
    fixed_mb = (maps["map1_16sc2"].nbytes + maps["map2_16uc1"].nbytes) / 1e6
    float_mb = (maps["map_x_32f"].nbytes + maps["map_y_32f"].nbytes) / 1e6
    P = np.array(entries[0]["P"])[:, :3]
    rng = np.random.default_rng(0)
    m1, m2, mx, my = (maps[k] for k in ("map1_16sc2", "map2_16uc1", "map_x_32f", "map_y_32f"))
    rows = []
    for label, frame in (
        ("grey", rng.integers(0, 256, (h, w), np.uint8)),
        ("BGR", rng.integers(0, 256, (h, w, 3), np.uint8)),
    ):
        fixed = _time(lambda f=frame: cv2.remap(f, m1, m2, cv2.INTER_LINEAR), repeats)
        floats = _time(lambda f=frame: cv2.remap(f, mx, my, cv2.INTER_LINEAR), repeats)

        def each_frame(f=frame):
            a, b = cv2.initUndistortRectifyMap(K, D, None, P, size, cv2.CV_16SC2)
            return cv2.remap(f, a, b, cv2.INTER_LINEAR)

        per_frame = _time(each_frame, max(5, repeats // 5))
        undistort = _time(lambda f=frame: cv2.undistort(f, K, D, None, P), max(5, repeats // 5))
        rows.append(
            f"| {w}x{h} | {label} | {threads} | {fixed} | {floats} | {per_frame} | {undistort} "
            f"| {fixed_mb:.2f} / {float_mb:.2f} | {load_ms:.1f} |"
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=50)
    parser.add_argument("--sizes", nargs="+", default=["640x480", "1280x960"])
    args = parser.parse_args()
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes]
    default_threads = cv2.getNumThreads()
    print("# bench_lut: remap time per frame, LUT against computing the map each frame\n")
    print("Times: best / median wall ms over the repeats (best CPU ms of the process in brackets).\n")
    print(
        f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, host {platform.node()}, {cpu_model()}, "
        f"{os.cpu_count()} CPUs, load {load_1min():.2f}; Python {platform.python_version()}, "
        f"OpenCV {cv2.__version__}, numpy {np.__version__}; {args.repeats} repeats (map each frame: "
        f"{max(5, args.repeats // 5)})\n"
    )
    print(
        "| size | frame | cv2 threads | fixed-point remap | float remap "
        "| map each frame (initUndistortRectifyMap + remap) | cv2.undistort "
        "| maps MB fixed / float | np.load of the 4 maps ms |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for threads in (default_threads, 1):
        cv2.setNumThreads(threads)
        for size in sizes:
            for row in run(size, args.repeats, threads):
                print(row)
    cv2.setNumThreads(default_threads)
    print(f"\nload after: {load_1min():.2f}")


if __name__ == "__main__":
    main()
