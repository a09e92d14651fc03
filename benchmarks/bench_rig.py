"""Rig benchmark: calibctl's stereo solve next to a plain cv2.stereoCalibrate script on the same files.

    .venv/bin/python benchmarks/bench_rig.py [--repeats 2]

Sets: a rendered 75 mm pair (``calibctl synth --rig 2 --views 14 --baseline-mm 75 --seed 7``, truth
known), opencv-left-right (13 pairs, square size unknown: baselines in squares, shown as "mm" of a 1 m
square) and baka-stereo (30 pairs, 23 mm nominal). calibctl: ``solve_rig_folders`` end to end
(detection, per-camera self-calibration with model opencv-default like the plain script, the rig
gate, cv2.stereoCalibrateExtended, covariance, 5-fold held-out epipolar error, loop closure n/a).
Plain: benchmarks/plain_stereo.py (findChessboardCorners + cornerSubPix 11x11, calibrateCamera flags 0
per camera, stereoCalibrate CALIB_FIX_INTRINSIC); its epipolar error is on the fitted pairs (it has no
held-out split). Time: best of ``--repeats`` wall-clock runs, detection included in both.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from machine import cpu_model  # benchmarks/machine.py (scripts run from benchmarks/)
from plain_stereo import plain_stereo

from calibctl.core.board.board_spec import BoardSpec
from calibctl.errors import CalibctlError
from calibctl.workflows.rig.rig_folders import solve_rig_folders
from calibctl.workflows.synth.synth_rig import run_synth_rig

DATASETS = Path(
    os.environ.get("CALIBCTL_TEST_DATASETS", Path(__file__).resolve().parents[2] / "shared" / "datasets")
)
if not DATASETS.is_dir():
    DATASETS = Path("/work/shared/datasets")


def _calibctl(left: Path, right: Path, board: BoardSpec) -> dict[str, object]:
    start = time.perf_counter()
    try:
        run = solve_rig_folders({"left": left, "right": right}, board, model="opencv-default")
    except CalibctlError as exc:
        return {"refused": exc.message.split(";")[0], "time_s": time.perf_counter() - start}
    elapsed = time.perf_counter() - start
    assert run.solution is not None and run.holdout is not None
    edge, pair = run.solution.tree.edges[0], run.holdout.pairs[0]
    return {
        "baseline_mm": edge.translation_mm,
        "sigma_mm": edge.sigma_translation_mm,
        "rotation_deg": edge.rotation_deg,
        "sigma_deg": edge.sigma_rotation_deg,
        "epipolar_rms_px": pair.epipolar_rms_px,
        "rectified_rms_px": pair.rectified_rms_px,
        "pairs": len(run.solution.views.frames),
        "time_s": elapsed,
    }


def _best(fn, repeats: int) -> dict[str, object]:
    return min((fn() for _ in range(repeats)), key=lambda r: float(r["time_s"]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        synth = Path(tmp) / "rig"
        run_synth_rig(synth, 2, seed=7, frames=14, baseline_mm=75.0)
        truth = json.loads((synth / "rig_truth.json").read_text())
        T_true = np.array(truth["cameras"][1]["T_root_cam"])
        true_mm = float(np.linalg.norm(T_true[:3, 3]) * 1e3)
        true_deg = float(np.rad2deg(np.linalg.norm(cv2.Rodrigues(T_true[:3, :3])[0])))
        olr = Path(tmp) / "olr"
        for side in ("left", "right"):
            (olr / side).mkdir(parents=True)
            for p in (DATASETS / "opencv-left-right").glob(f"{side}*.jpg"):
                (olr / side / p.name).write_bytes(p.read_bytes())
        sets = [
            (
                f"rendered 75 mm pair (truth {true_mm:.3f} mm, {true_deg:.4f} deg)",
                synth / "CAM0",
                synth / "CAM1",
                9,
                6,
                0.025,
            ),
            ("opencv-left-right (1 square = 1 m)", olr / "left", olr / "right", 9, 6, 1.0),
            (
                "baka-stereo (23 mm nominal)",
                DATASETS / "baka-stereo" / "left",
                DATASETS / "baka-stereo" / "right",
                7,
                10,
                0.023,
            ),
        ]
        print(f"## Rig benchmark {dt.datetime.now().astimezone().isoformat(timespec='seconds')}\n")
        print(
            f"{cpu_model()}, nproc {len(os.sched_getaffinity(0))}, load average before "
            f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}; OpenCV {cv2.__version__}; best of "
            f"{args.repeats}\n"
        )
        print(
            "| set | tool | pairs | baseline mm | rotation deg | epipolar RMS px | rectified rows RMS px | "
            "time s |"
        )
        print("|---|---|---|---|---|---|---|---|")
        for name, left, right, cols, rows, square in sets:
            board = BoardSpec.chessboard(cols, rows, square)
            mine = _best(
                lambda left=left, right=right, board=board: _calibctl(left, right, board), args.repeats
            )
            plain = _best(
                lambda left=left, right=right, c=cols, r=rows, s=square: plain_stereo(left, right, c, r, s),
                args.repeats,
            )
            if "refused" in mine:
                print(
                    f"| {name} | calibctl | - | refused (exit 2): {mine['refused']} | - | - | - | "
                    f"{mine['time_s']:.2f} |"
                )
            else:
                print(
                    f"| {name} | calibctl | {mine['pairs']} | {mine['baseline_mm']:.3f} +/- "
                    f"{mine['sigma_mm']:.3f} | "
                    f"{mine['rotation_deg']:.4f} +/- {mine['sigma_deg']:.4f} | "
                    f"{mine['epipolar_rms_px']:.3f} (held-out) | "
                    f"{mine['rectified_rms_px']:.3f} (held-out) | {mine['time_s']:.2f} |"
                )
            print(
                f"| {name} | plain OpenCV | {plain['pairs']} | {plain['baseline_m'] * 1e3:.3f} | "
                f"{plain['rotation_deg']:.4f} | {plain['epipolar_rms_px']:.3f} (fit; stereo RMS "
                f"{plain['stereo_rms_px']:.3f}) | - | {plain['time_s']:.2f} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
