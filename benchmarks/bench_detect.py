"""Detection benchmark: throughput vs a plain OpenCV loop, worst-case board-free frames, accuracy per detector.

    .venv/bin/python benchmarks/bench_detect.py [--repeats 3] [--out benchmarks/out/bench_detect.md]

1. Throughput on 20 rendered images (``calibctl synth``'s renderer, scenario good) at 1280x960 and
   640x480: calibctl's parallel folder runner (``classify_files``, 2 workers, including the process pool
   start, sha256 and blur check) against a plain sequential loop (imread + findChessboardCorners with
   OpenCV's default flags + cornerSubPix 11x11) on the same PNG files. Best of ``--repeats``.
2. Worst case for a 4000x3000 frame without a board: ``detect_chessboard`` on frames built to be hard
   (sensor noise, clutter of rectangles, a chessboard of the wrong size, a no-board real photo upscaled).
3. Accuracy: mean and 95th-percentile corner error against the renderer's truth, per detector.

Prints a markdown report (machine, OpenCV version, date) and writes it to ``--out``.
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
from machine import cpu_model  # benchmarks/machine.py (scripts run from benchmarks/)

from calibctl.core.board_spec import BoardSpec
from calibctl.core.detect import detect_chessboard
from calibctl.core.image_outcomes import classify_files
from calibctl.core.synth import Photometry, PinholeCamera, render_view, true_corners_px
from calibctl.core.synth_scenes import scenario_poses

BOARD = BoardSpec.chessboard(9, 6, 0.025)
N_IMAGES = 20
SIZES = ((1280, 960), (640, 480))
NO_BOARD_SIZE = (4000, 3000)
CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.001)
UDACITY_NO_BOARD = Path("/work/shared/datasets/udacity-camcal/calibration1.jpg")




def render_set(folder: Path, size: tuple[int, int], seed: int) -> tuple[list[Path], list[np.ndarray]]:
    camera = PinholeCamera.seed_reference(size)
    rng = np.random.default_rng(seed)
    paths, truths = [], []
    for i, T in enumerate(scenario_poses("good", camera, BOARD, N_IMAGES, rng)):
        path = folder / f"{size[0]}-{i:02d}.png"
        cv2.imwrite(str(path), render_view(camera, BOARD, T, rng, Photometry.random(rng)))
        paths.append(path)
        truths.append(true_corners_px(camera, BOARD, T))
    return paths, truths


def plain_loop(paths: list[Path]) -> int:
    found = 0
    for path in paths:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        ok, corners = cv2.findChessboardCorners(gray, (BOARD.cols, BOARD.rows))
        if ok:
            cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), CRITERIA)
            found += 1
    return found


def best_time(fn, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def no_board_frames() -> dict[str, np.ndarray]:
    width, height = NO_BOARD_SIZE
    rng = np.random.default_rng(0)
    frames = {"sensor noise": rng.integers(0, 256, (height, width), dtype=np.uint8)}
    clutter = np.full((height, width), 128, np.uint8)
    for _ in range(3000):
        x, y = (int(v) for v in rng.integers(0, (width, height)))
        w, h = (int(v) for v in rng.integers(20, 200, 2))
        cv2.rectangle(clutter, (x, y), (x + w, y + h), int(rng.integers(0, 256)), -1)
    frames["3000 random rectangles"] = clutter
    frames["39x29 chessboard (wrong size)"] = (np.kron(np.indices((30, 40)).sum(0) % 2, np.ones((100, 100)))
                                               * 255).astype(np.uint8)[:height, :width]
    if UDACITY_NO_BOARD.is_file():
        photo = cv2.imread(str(UDACITY_NO_BOARD), cv2.IMREAD_GRAYSCALE)
        frames["udacity calibration1 upscaled"] = cv2.resize(photo, NO_BOARD_SIZE, interpolation=cv2.INTER_CUBIC)
    return frames


def raw_detectors() -> dict[str, object]:
    def classic(gray: np.ndarray, win: int = 5):
        ok, c = cv2.findChessboardCorners(gray, (BOARD.cols, BOARD.rows))
        return cv2.cornerSubPix(gray, c, (win, win), (-1, -1), CRITERIA) if ok else None

    def sb(flags: int):
        return lambda gray: (lambda r: r[1] if r[0] else None)(
            cv2.findChessboardCornersSB(gray, (BOARD.cols, BOARD.rows), flags=flags))

    def ours(gray: np.ndarray):
        det, _ = detect_chessboard(gray, BOARD.cols, BOARD.rows)
        return None if det is None else det.corners_px

    return {"findChessboardCorners + cornerSubPix 11x11 (plain)": classic,
            "findChessboardCornersSB": sb(0),
            "findChessboardCornersSB + ACCURACY": sb(cv2.CALIB_CB_ACCURACY),
            "calibctl detect_chessboard (classic, SB fallback, adaptive subpix)": ours}


def accuracy(paths: list[Path], truths: list[np.ndarray]) -> list[tuple[str, int, float, float, float]]:
    rows = []
    images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in paths]
    for name, fn in raw_detectors().items():
        errors, times = [], []
        for gray, truth in zip(images, truths, strict=True):
            start = time.perf_counter()
            corners = fn(gray)
            times.append(time.perf_counter() - start)
            if corners is None:
                continue
            c = np.asarray(corners, np.float64).reshape(-1, 2)
            e1, e2 = np.linalg.norm(c - truth, axis=1), np.linalg.norm(c[::-1] - truth, axis=1)
            errors.append(e1 if e1.mean() <= e2.mean() else e2)  # raw OpenCV order is not canonical
        err = np.concatenate(errors) if errors else np.array([np.nan])
        rows.append((name, len(errors), float(err.mean()), float(np.percentile(err, 95)), statistics.mean(times)))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "out" / "bench_detect.md")
    args = parser.parse_args()
    lines = [f"## Detection benchmark ({dt.date.today().isoformat()})", "",
             f"Machine: {os.cpu_count()} CPUs ({cpu_model()}), Python {platform.python_version()}, "
             f"OpenCV {cv2.__version__}, numpy {np.__version__}. Shared machine: timings are best of "
             f"{args.repeats}.", ""]
    with tempfile.TemporaryDirectory() as tmp:
        sets = {size: render_set(Path(tmp), size, seed=20 + i) for i, size in enumerate(SIZES)}
        lines += ["### Throughput, 20 images", "",
                  "calibctl = ``classify_files(paths, workers=2)``: sha256, decode, detection, refinement, blur check.",
                  "Process pool: its first run in a process also starts the fork server (imports cv2).", "",
                  "| size | plain sequential loop | calibctl, 2 threads (default) | speed-up | "
                  "calibctl, 1 worker | 2 processes, first run | 2 processes, later runs |",
                  "|---|---|---|---|---|---|---|"]
        for size, (paths, _) in sets.items():
            t_plain, found = best_time(lambda p=paths: plain_loop(p), args.repeats)
            t_threads, outcomes = best_time(lambda p=paths: classify_files(p, BOARD, workers=2), args.repeats)
            t_one, _ = best_time(lambda p=paths: classify_files(p, BOARD, workers=1), args.repeats)
            runs = []
            for _ in range(args.repeats + 1):
                start = time.perf_counter()
                classify_files(paths, BOARD, workers=2, executor="process")
                runs.append(time.perf_counter() - start)
            accepted = sum(o.accepted for o in outcomes)
            lines.append(f"| {size[0]}x{size[1]} | {t_plain * 1e3:.0f} ms ({found}/20 found) | "
                         f"{t_threads * 1e3:.0f} ms ({accepted}/20) | {t_plain / t_threads:.2f}x | "
                         f"{t_one * 1e3:.0f} ms | {runs[0] * 1e3:.0f} ms | {min(runs[1:]) * 1e3:.0f} ms |")
        lines += ["", f"### Worst case: {NO_BOARD_SIZE[0]}x{NO_BOARD_SIZE[1]} frame without a board (one thread)", "",
                  "| frame | detect_chessboard | reason |", "|---|---|---|"]
        cv2.setNumThreads(1)
        worst = 0.0
        for name, frame in no_board_frames().items():
            t, (det, why) = best_time(lambda f=frame: detect_chessboard(f, BOARD.cols, BOARD.rows), args.repeats)
            worst = max(worst, t)
            lines.append(f"| {name} | {t * 1e3:.0f} ms | {'FOUND' if det else why} |")
        lines += ["", f"Worst: {worst * 1e3:.0f} ms (target < 1000 ms).", "",
                  "### Accuracy against truth (rendered, seed lens k1 = -0.28)", "",
                  "| size | detector | found | mean err px | p95 err px | ms/image |", "|---|---|---|---|---|---|"]
        for size, (paths, truths) in sets.items():
            for name, n, mean, p95, t in accuracy(paths, truths):
                lines.append(f"| {size[0]}x{size[1]} | {name} | {n}/20 | {mean:.4f} | {p95:.4f} | {t * 1e3:.0f} |")
    report = "\n".join(lines) + "\n"
    print(report)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(report, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
