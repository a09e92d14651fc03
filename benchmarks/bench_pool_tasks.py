"""The warm pool's cost per image, split between the calling process and the workers, one file a task
against ``task_chunks``, beside a plain ``multiprocessing.Pool(2).map``; in one process, alternating.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_pool_tasks.py RENDERED_96 [--rounds 8] [--summarize]

RENDERED_96: ``calibctl synth OUT --views 96 --size 1280x960``. The pool is warmed first, so no start-up is
counted (``bench_parallel_detect.py`` counts it, in fresh processes). Per path and round: wall
(perf_counter), the caller's CPU (``time.process_time``: every thread of this process, the executor's
manager and queue-feeder threads included) and the workers' CPU (calibctl: /proc/PID/stat of the pool's
workers, Linux; they are the fork server's children, not this process's. Plain pool: getrusage
RUSAGE_CHILDREN, its workers are forked and waited for). "one file a task" is the code before
``task_chunks`` (it is replaced by one-file runs for those rounds); the outcomes of both are checked equal.
``--summarize``: each worker also returns ``sized_half`` of its image, as a folder capture asks.
Prints a markdown table with machine, date and load; least and median over the rounds.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import resource
import statistics
import sys
import time
from collections.abc import Callable
from multiprocessing import get_context
from pathlib import Path

import cv2
from machine import cpu_model  # benchmarks/machine.py (scripts run from benchmarks/)

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import image_outcomes, worker_pool
from calibctl.core.capture.image_circle import sized_half

BOARD = BoardSpec.chessboard(9, 6, 0.025)
FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.001)


def plain_detect(path: str) -> object:
    """bench_parallel_detect.py's PLAIN worker: imread + findChessboardCorners + cornerSubPix 11x11."""
    gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    found, corners = cv2.findChessboardCorners(gray, (9, 6), flags=FLAGS)
    return cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), CRIT) if found else None


def proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rendered", type=Path)
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--summarize", action="store_true")
    args = parser.parse_args()
    paths = image_outcomes.list_images(args.rendered)
    worker_pool.warm(2)
    pool = worker_pool.process_pool(2)
    chunked = image_outcomes.task_chunks
    policies: dict[str, Callable[[list[int], int], list[list[int]]]] = {
        "one file a task (before)": lambda todo, workers: [[i] for i in todo],
        "task_chunks": chunked,
    }
    load = os.getloadavg()
    print(
        f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {len(os.sched_getaffinity(0))} cores "
        f"available, Python {platform.python_version()}, load average {load[0]:.2f} / {load[1]:.2f} / "
        f"{load[2]:.2f} at start; {len(paths)} images, warm pool of 2, {args.rounds} rounds alternating, "
        f"summarize={'sized_half' if args.summarize else 'None'}\n"
    )
    runs: dict[str, list[tuple[float, float, float]]] = {}
    reference = None
    for _ in range(args.rounds):
        for name, policy in policies.items():
            image_outcomes.task_chunks = policy  # type: ignore[assignment]
            pids = list(pool._processes)  # noqa: SLF001 - the workers' CPU is read from /proc
            workers0, caller0, t0 = sum(map(proc_cpu_s, pids)), time.process_time(), time.perf_counter()
            out = image_outcomes.classify_files(
                paths,
                BOARD,
                workers=2,
                executor="process",
                summarize=sized_half if args.summarize else None,
                on_summary=(lambda summary: None) if args.summarize else None,
            )
            wall, caller = time.perf_counter() - t0, time.process_time() - caller0
            runs.setdefault(name, []).append((wall, caller, sum(map(proc_cpu_s, pids)) - workers0))
            key = [(o.name, o.status, None if o.corners_px is None else o.corners_px.tobytes()) for o in out]
            assert reference is None or key == reference, "outcomes differ"
            reference = key
        image_outcomes.task_chunks = chunked
        children0, caller0, t0 = children_cpu_s(), time.process_time(), time.perf_counter()
        with get_context("fork").Pool(2) as plain:  # as the plain script's Pool (Linux's default)
            plain.map(plain_detect, [str(p) for p in paths])
        runs.setdefault("plain Pool(2).map (fork, its start included)", []).append(
            (time.perf_counter() - t0, time.process_time() - caller0, children_cpu_s() - children0)
        )
    print(
        "| path | wall s least | wall s median | caller CPU s least | median | workers CPU s least | median "
        "| workers CPU per image ms |\n|---|---|---|---|---|---|---|---|"
    )
    for name, rows in runs.items():
        walls, callers, workers = zip(*rows, strict=True)
        print(
            f"| {name} | {min(walls):.3f} | {statistics.median(walls):.3f} | {min(callers):.3f} | "
            f"{statistics.median(callers):.3f} | {min(workers):.2f} | {statistics.median(workers):.2f} | "
            f"{1000 * statistics.median(workers) / len(paths):.1f} |"
        )
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")
    worker_pool.shutdown_pool()


if __name__ == "__main__":
    sys.exit(main())
