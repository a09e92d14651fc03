"""calibctl report on real photos: how long a report takes, how big it is, and its centre uncertainty beside
plain OpenCV's numbers on the same files.

Set: ../shared/datasets/opencv-left-right, the 13 left images (640x480), calibrated by calibctl (board 9x6,
25 mm, model k1k2). calibctl side: ``workflows.report.report.gather`` (store reads, residuals, uncertainty
map) and
``render_html`` timed separately, best and median of N after a warm-up, report size, byte-identical check.
Plain side on the same files: findChessboardCorners + cornerSubPix + cv2.calibrateCameraExtended with the
same flags, its wall time, and its stdDeviationsIntrinsics for cx and cy, to set beside the report's
projection one-sigma at the image centre (which is mostly the principal point's uncertainty).

Run: python benchmarks/bench_report.py [--repeats N]   (default 5)
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from machine import cpu_model  # noqa: E402

from calibctl.cli.main import app  # noqa: E402
from calibctl.config import load_settings  # noqa: E402
from calibctl.workflows.report import report as report_workflow  # noqa: E402
from calibctl.workflows.report.report_html import render_html  # noqa: E402

DATASET = Path(os.environ.get("CALIBCTL_TEST_DATASETS", "/work/shared/datasets")) / "opencv-left-right"
FLAGS = cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_ASPECT_RATIO


def timed(fn, repeats: int) -> tuple[float, float, object]:
    result = fn()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times), result


def calibctl_store(root: Path) -> str:
    left = root / "left"
    left.mkdir()
    for path in sorted(DATASET.glob("left*.jpg")):
        shutil.copy(path, left / path.name)
    url = f"sqlite:///{root / 'store.db'}"
    runner = CliRunner()
    for args in (
        [
            "board",
            "add",
            "A17",
            "--kind",
            "chessboard",
            "--cols",
            "9",
            "--rows",
            "6",
            "--square-mm",
            "25",
            "--uncertainty-mm",
            "0.02",
            "--instrument",
            "calipers",
            "--measured-by",
            "bench",
            "--measured-on",
            "2026-11-23",
        ],
        ["calibrate", "--serial", "LEFT-01", "--board", "A17", "--source", str(left)],
    ):
        done = runner.invoke(app, ["--db", url, *args])
        if done.exit_code != 0:
            raise SystemExit(done.output)
    return url


def plain(repeats: int) -> tuple[float, float, float, float]:
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025

    def run():
        points = []
        for path in sorted(DATASET.glob("left*.jpg")):
            gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            ok, corners = cv2.findChessboardCorners(
                gray, (9, 6), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
            )
            if ok:
                criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
                points.append(cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria))
        return cv2.calibrateCameraExtended(
            [obj] * len(points), points, (640, 480), np.eye(3), None, flags=FLAGS
        )

    best, median, out = timed(run, repeats)
    std = out[5].ravel()
    return best, median, float(std[2]), float(std[3])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(
        f"# bench_report: {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} cores ({cpu_model()}), "
        f"load {os.getloadavg()[0]:.1f}; Python {platform.python_version()}, OpenCV {cv2.__version__}\n"
    )
    with tempfile.TemporaryDirectory() as tmp:
        url = calibctl_store(Path(tmp))
        settings = load_settings(db=url, env={})
        g_best, g_med, data = timed(lambda: report_workflow.gather(settings, "LEFT-01"), args.repeats)
        r_best, r_med, html = timed(lambda: render_html(data), args.repeats)
        again = render_html(report_workflow.gather(settings, "LEFT-01"))
    art = data.artifact
    m = data.uncertainty
    centre = float(m.sigma_px[len(m.v_px) // 2, len(m.u_px) // 2])
    p_best, p_med, p_cx, p_cy = plain(args.repeats)
    corners = sum(len(v.corners_px) for v in data.views)
    print("| side | what | best s | median s | result |")
    print("|---|---|---|---|---|")
    print(
        f"| calibctl | report: gather (store, residuals, uncertainty map) | {g_best:.3f} | {g_med:.3f} | "
        f"{len(data.views)} views, {corners} corners |"
    )
    print(
        f"| calibctl | report: render HTML | {r_best:.3f} | {r_med:.3f} | {len(html.encode()):,} bytes, "
        f"byte-identical on regeneration: {html == again} |"
    )
    print(
        f"| plain OpenCV | detect + calibrateCameraExtended | {p_best:.3f} | {p_med:.3f} | "
        f"sigma cx {p_cx:.3f} px, sigma cy {p_cy:.3f} px |"
    )
    print(
        f"\ncalibctl: sigma cx {art.stdev.sigma['cx']:.3f} px, sigma cy {art.stdev.sigma['cy']:.3f} px; "
        f"projection one-sigma at the image centre {centre:.3f} px, worst {float(m.sigma_px.max()):.3f} px; "
        f"fit RMS {art.rms_px:.3f} px"
    )


if __name__ == "__main__":
    main()
