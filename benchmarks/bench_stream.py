"""A video's frames detected by calibctl at 1 job and at every core, beside a plain OpenCV loop and a plain
pool.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_stream.py [--size 1280x720] [--repeats 3]

The video is ``calibctl synth --scenario video`` at ``--size`` (74 frames, 8 still key poses; rendered once
into
a temporary folder). In one process, the paths taking turns, ``--repeats`` rounds, best wall time and least
CPU:
  * calibctl ``capture`` of the video into a fresh SQLite store at jobs 1 and jobs = cores (frames detected
  ahead
    on threads and settled in order, ``workflows.camera.capture._detected_frames``): decode, detection, frame
    selection and its live gates, the kept frames encoded and stored, the session's gates; plus the CPU time
    of the calling (main) thread, the part that cannot spread over cores;
  * the plain script's detection alone: VideoCapture.read + cvtColor + findChessboardCorners (ADAPTIVE_THRESH
  |
    NORMALIZE_IMAGE) + cornerSubPix 11x11 on every frame, sequentially and on a multiprocessing.Pool of cores
    workers (frames pickled to them; fork, Linux's default, the pool's start included).
The plain rows select nothing and store nothing: they are what a user's own loop costs before any of that.
calibctl's frame count and kept views must be equal at both job counts (checked, printed). Nothing is asserted
about time; the load average is printed beside each row.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

import cv2
from machine import cpu_model, load_1min

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.001)


def plain_detect(image):
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    found, corners = cv2.findChessboardCorners(gray, (9, 6), flags=FLAGS)
    return None if not found else cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), CRIT)


def plain_frames(video: Path):
    capture = cv2.VideoCapture(str(video))
    while True:
        ok, image = capture.read()
        if not ok:
            break
        yield image
    capture.release()


def plain(video: Path, jobs: int) -> int:
    if jobs == 1:
        return sum(plain_detect(image) is not None for image in plain_frames(video))
    from multiprocessing import Pool

    with Pool(jobs) as pool:
        return sum(c is not None for c in pool.imap(plain_detect, plain_frames(video), chunksize=2))


def cpu_s() -> float:
    usage, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    from calibctl.config import load_settings
    from calibctl.store.repository import Store
    from calibctl.workflows.camera.capture import CaptureRequest, capture
    from calibctl.workflows.synth.synth import run_synth
    from tests.artifacts.factories import measured_board

    cores = len(os.sched_getaffinity(0))
    width, height = (int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        run_synth(work / "video", "video", seed=1, image_size=(width, height))
        video = work / "video" / "video.avi"
        url = f"sqlite:///{work / 'store.db'}"
        with Store.open(url) as store:
            store.add_board(measured_board("A17", square_mm=25.0))
        settings = load_settings(db=url, env={})
        load = os.getloadavg()
        print(
            f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {cores} cores available, Python "
            f"{platform.python_version()}, OpenCV {cv2.__version__}, load average {load[0]:.2f} / "
            f"{load[1]:.2f} / "
            f"{load[2]:.2f} at start; video {width}x{height}, best of {args.repeats}\n"
        )

        def calibctl(jobs: int) -> str:
            result = capture(settings, CaptureRequest("BENCH-1", "A17", str(video), jobs=jobs))
            return f"{len(result.session.outcomes)} frames, {len(result.session.views)} views kept"

        paths = {
            "calibctl capture, jobs 1": lambda: calibctl(1),
            f"calibctl capture, jobs {cores}": lambda: calibctl(cores),
            "plain loop, sequential": lambda: f"{plain(video, 1)} boards",
            f"plain loop, Pool({cores})": lambda: f"{plain(video, cores)} boards",
        }
        best: dict[str, tuple[float, float, float, str, float]] = {}
        for _ in range(args.repeats):
            for name, path in paths.items():
                load_now = load_1min()
                t, c, m = time.perf_counter(), cpu_s(), time.thread_time()
                what = path()
                wall, cpu, main_cpu = time.perf_counter() - t, cpu_s() - c, time.thread_time() - m
                old = best.get(name)
                best[name] = (
                    min(wall, old[0]) if old else wall,
                    min(cpu, old[1]) if old else cpu,
                    min(main_cpu, old[2]) if old else main_cpu,
                    what,
                    load_now if old is None or wall < old[0] else old[4],
                )
        if best["calibctl capture, jobs 1"][3] != best[f"calibctl capture, jobs {cores}"][3]:
            raise SystemExit("calibctl's outcomes differ between job counts")
        base = best["plain loop, sequential"][0]
        print("| path | wall s | / plain sequential | CPU s | main-thread CPU s | found | load |")
        print("|---|---|---|---|---|---|---|")
        for name, (wall, cpu, main_cpu, what, load_at) in best.items():
            main_text = f"{main_cpu:.3f}" if name.startswith("calibctl") else "-"
            print(
                f"| {name} | {wall:.3f} | {wall / base:.2f}x | {cpu:.3f} | {main_text} | {what} | "
                f"{load_at:.1f} |"
            )


if __name__ == "__main__":
    main()
