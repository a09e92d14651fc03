"""Per-view tilt readout against truth: calibctl's gates (old homography readout and the new one) and a
plain OpenCV solve, on the same views.

Views: ``synth_scenes.sweep_poses`` (tilt uniform 0-50 deg, any direction, board centre anywhere in the
frame, edges included), 20 views per session, the seed lens (f = 800 px at 640x480, k1 = -0.28).
  * projected: true corners + 0.1 px Gaussian noise, N sessions at 1280x960 and at 640x480;
  * rendered: ``--render S`` sessions rendered at 1280x960 (core/synth/pinhole.py) and detected by calibctl's
    detector (slower: about 1 s per view).
Readouts: "old" = the pre-issue-8 gates (homography, Zhang's f with c at the centre, lens ignored);
"calibctl" = ``evaluate_gates`` now (calibctl.core.capture.tilt); "plain OpenCV" = cv2.calibrateCamera with
flags 0 on the session, tilt from its rvecs (what a user would do with the whole solve).

Run: python benchmarks/bench_tilt.py [--sessions N] [--render S]   (default 20, 2)
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
from datetime import UTC, datetime

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model  # noqa: E402

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.board.views import BoardView  # noqa: E402
from calibctl.core.capture.detect import detect_board  # noqa: E402
from calibctl.core.capture.gates import estimate_focal_px, evaluate_gates, view_homography, view_tilt  # noqa: E402
from calibctl.core.capture.tilt import normal_tilt_direction  # noqa: E402
from calibctl.core.synth.pinhole import PinholeCamera, render_view, true_corners_px  # noqa: E402
from calibctl.core.synth.scenes import sweep_poses  # noqa: E402

BOARD = BoardSpec.chessboard(9, 6, 0.025)
NOISE_PX = 0.1
VIEWS = 20


def old_readout(views: list[BoardView], size: tuple[int, int]) -> list[float]:
    model = BOARD.object_points()[:, :2]
    Hs = [view_homography(model[v.corner_ids], v.corners_px) for v in views]
    f = estimate_focal_px([H for H in Hs if H is not None], size) or math.hypot(*size)
    return [view_tilt(H, size, f)[0] if H is not None else math.nan for H in Hs]


def opencv_readout(views: list[BoardView], size: tuple[int, int]) -> list[float]:
    obj = [BOARD.object_points()[v.corner_ids].astype(np.float32) for v in views]
    img = [v.corners_px.astype(np.float32) for v in views]
    _, _, _, rvecs, _ = cv2.calibrateCamera(obj, img, size, None, None)
    return [normal_tilt_direction(np.ravel(r))[0] for r in rvecs]


def new_readout(views: list[BoardView], size: tuple[int, int]) -> list[float]:
    report = evaluate_gates(views, BOARD.object_points(), size)
    by_name = {g.name: g.tilt_deg for g in report.views}
    return [by_name.get(v.name, math.nan) for v in views]


def session(size: tuple[int, int], seed: int, render: bool) -> tuple[list[BoardView], np.ndarray]:
    camera = PinholeCamera.seed_reference(size)
    rng = np.random.default_rng(seed)
    poses, truth = sweep_poses(camera, BOARD, VIEWS, rng)
    views, kept = [], []
    for i, T in enumerate(poses):
        if render:
            det, _ = detect_board(render_view(camera, BOARD, T, rng), BOARD)
            if det is None:
                continue
            views.append(BoardView(f"v{i}", det.corner_ids, det.corners_px))
        else:
            px = true_corners_px(camera, BOARD, T) + rng.normal(0.0, NOISE_PX, (BOARD.n_corners, 2))
            views.append(BoardView(f"v{i}", np.arange(BOARD.n_corners), px))
        kept.append(truth[i])
    return views, np.array(kept)


def summary(name: str, errors: np.ndarray, truth: np.ndarray) -> str:
    ok = np.isfinite(errors)
    e, t = errors[ok], truth[ok]
    flat = t < 4.0
    flat_max = f"{(t[flat] + e[flat]).max():.1f}" if flat.any() else "-"
    return (
        f"| {name} | {ok.sum()} | {e.mean():+.2f} | {e.std():.2f} | {np.abs(e).max():.2f} | "
        f"{100 * np.mean(np.abs(e) > 2.0):.0f} % | {flat.sum()} | {flat_max} |"
    )


def run(size: tuple[int, int], seeds: range, render: bool) -> list[str]:
    rows = {
        "old gates (homography, lens ignored)": [],
        "calibctl gates": [],
        "plain OpenCV calibrateCamera": [],
    }
    truths = []
    for seed in seeds:
        views, truth = session(size, seed, render)
        truths.append(truth)
        for name, fn in zip(rows, (old_readout, new_readout, opencv_readout), strict=True):
            rows[name].append(np.array(fn(views, size)) - truth)
    truth_all = np.concatenate(truths)
    kind = "rendered + detected" if render else f"projected + {NOISE_PX} px noise"
    out = [
        f"\n{size[0]}x{size[1]}, {kind}, {len(seeds)} sessions x {VIEWS} views (seeds {seeds.start}-"
        f"{seeds.stop - 1}); tilt error = read - true, deg\n",
        "| readout | views | mean | sd | max abs | > 2 deg off | views truly < 4 deg | max read on them |",
        "|---|---|---|---|---|---|---|---|",
    ]
    out += [summary(name, np.concatenate(err), truth_all) for name, err in rows.items()]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=20)
    parser.add_argument("--render", type=int, default=2)
    args = parser.parse_args()
    print(
        f"# bench_tilt: {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} cores ({cpu_model()}), "
        f"load {os.getloadavg()[0]:.1f}; Python {platform.python_version()}, OpenCV {cv2.__version__}"
    )
    lines = run((1280, 960), range(args.sessions), False) + run((640, 480), range(args.sessions), False)
    if args.render:
        lines += run((1280, 960), range(1000, 1000 + args.render), True)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
