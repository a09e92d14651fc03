"""Tilt gate on rendered circular fisheyes against the renders' truth.

Sessions: ``calibctl synth --fisheye`` renders, 640x480, 12 views, "good" scenario, seeds 0..N-1 at each
field of view; corners found by calibctl's detector; the gates run with the render's image circle.
Per session: does the tilt gate pass, and does it pass exactly when the true poses have three tilt
directions at least 90 deg apart with views at 20-45 deg ("truth")? Per view: |read tilt - true tilt|.
CPU time of ``view_geometries`` (the lens fit and every pose) per session.

Run from a worktree: PYTHONPATH=$PWD python benchmarks/bench_fisheye_tilt.py [--seeds 24] [--fov 150 170 190]
(point PYTHONPATH at an older tree to measure its readout on the same renders).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture.detect import detect_board
from calibctl.core.capture.gates import evaluate_gates, view_geometries
from calibctl.core.capture.image_circle import ImageCircle
from calibctl.core.capture.tilt import distinct_directions
from calibctl.workflows.synth.synth import run_synth

SIZE = (640, 480)
SPEC = BoardSpec.chessboard(9, 6, 0.025)


def session(root: Path, fov_deg: float, seed: int) -> tuple[list[BoardView], dict, ImageCircle]:
    out = root / f"r{fov_deg:.0f}_{seed}"
    if not (out / "truth.json").exists():
        run_synth(out, "good", seed=seed, views=12, image_size=SIZE, fisheye_fov_deg=fov_deg)
    truth = json.loads((out / "truth.json").read_text())
    views = []
    for path in sorted(out.glob("view-*.png")):
        det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), SPEC)
        if det is not None:
            views.append(BoardView(path.name, det.corner_ids, det.corners_px))
    K = np.array(truth["camera"]["K"])
    return views, truth, ImageCircle(K[0, 2], K[1, 2], truth["camera"]["image_circle_px"], "given")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=24)
    parser.add_argument("--fov", type=float, nargs="+", default=[150.0, 170.0, 190.0])
    parser.add_argument("--renders", type=Path, default=Path(tempfile.gettempdir()) / "bench_fisheye_tilt")
    args = parser.parse_args()
    print(f"# bench_fisheye_tilt: load {os.getloadavg()[0]:.2f}; {args.seeds} seeds per field of view")
    print(
        "| fov deg | sessions | gate passes | truly 3 directions | gate = truth | views | median / p90 / max "
        "abs tilt error deg | CPU s per session (median) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for fov in args.fov:
        passes = truly = agree = 0
        errors: list[float] = []
        cpu: list[float] = []
        for seed in range(args.seeds):
            views, truth, circle = session(args.renders, fov, seed)
            by_file = {v["file"]: v for v in truth["views"]}
            passed = (
                evaluate_gates(views, SPEC.object_points(), SIZE, image_circle=circle).gate("tilt").passed
            )
            t0 = time.process_time()
            geo = view_geometries(views, SPEC.object_points(), SIZE)
            cpu.append(time.process_time() - t0)
            errors += [abs(g.tilt_deg - by_file[g.name]["tilt_deg"]) for g in geo.views]
            true_pass = (
                len(
                    distinct_directions(
                        [
                            by_file[v.name]["direction_deg"]
                            for v in views
                            if 20.0 <= by_file[v.name]["tilt_deg"] <= 45.0
                        ]
                    )
                )
                >= 3
            )
            passes += passed
            truly += true_pass
            agree += passed == true_pass
        e = np.array(errors)
        print(
            f"| {fov:.0f} | {args.seeds} | {passes} | {truly} | {agree} | {len(e)} | {np.median(e):.2f} / "
            f"{np.percentile(e, 90):.2f} / {e.max():.2f} | {np.median(cpu):.3f} |"
        )


if __name__ == "__main__":
    main()
