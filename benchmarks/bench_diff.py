"""`calibctl diff`'s error rates (docs/diff.md): how often an unchanged camera is flagged, how often a 0.3 %
focal change or a 1 px principal-point shift is caught, on seeded corner-level sessions and on real photos.

Corners: tests/core/compare/sessions.py (the seed's focal length and k1, k2 at 640x480, 30 views, 0.03 px
noise, solved k1k2); "misfit" solves the seed's full 5-term lens (p1 p2 k3 too) with the k1k2 model, so
each solve's model error depends on its views. Real: opencv-left-right's 13 left photos detected by
calibctl's detector, split at random into 7 + 6 views, each half solved k1k2 and diffed.

Run: python benchmarks/bench_diff.py [--pairs 100] [--splits 40]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import UTC, datetime

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from machine import cpu_model  # noqa: E402

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.capture.detect import detect_board  # noqa: E402
from calibctl.core.compare.lens import lens_from_solution  # noqa: E402
from calibctl.core.compare.projection_diff import projection_diff  # noqa: E402
from calibctl.core.intrinsics.solve import solve_intrinsics  # noqa: E402
from calibctl.core.synth.pinhole import PinholeCamera  # noqa: E402
from tests.core.compare.sessions import SIZE, solve, true_K  # noqa: E402
from tests.datasets import LEFT_RIGHT  # noqa: E402


def corner_rates(pairs: int) -> None:
    full = np.array(PinholeCamera.seed_reference(SIZE).dist, dtype=np.float64)
    cases = [("unchanged", true_K(), None), ("focal +0.3 %", true_K(focal_scale=1.003), None),
             ("cx +1 px", true_K(dcx_px=1.0), None), ("unchanged, k1k2 misfit", true_K(), full),
             ("focal +0.3 %, k1k2 misfit", true_K(focal_scale=1.003), full),
             ("cx +1 px, k1k2 misfit", true_K(dcx_px=1.0), full)]
    print("| case | flagged | median chi2 (dof) |\n|---|---|---|")
    for name, K_b, dist in cases:
        kw = {} if dist is None else {"dist": dist}
        flagged, stats, dof = 0, [], 0
        for i in range(pairs):
            r = projection_diff(lens_from_solution(solve(true_K(), 1000 + i, **kw)),
                                lens_from_solution(solve(K_b, 50_000 + i, **kw)))
            flagged += bool(r.significant)
            assert r.raw.test is not None
            stats.append(r.raw.test.statistic)
            dof = r.raw.test.dof
        print(f"| {name} | {flagged} / {pairs} ({100 * flagged / pairs:.1f} %) | {np.median(stats):.1f} ({dof}) |",
              flush=True)


def real_splits(splits: int) -> None:
    spec = BoardSpec.chessboard(9, 6, 0.025)
    obj_all = spec.object_points()
    views = []
    for path in sorted(LEFT_RIGHT.glob("left*.jpg")):
        det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), spec)
        assert det is not None, path
        views.append((obj_all[det.corner_ids], det.corners_px))
    rng = np.random.default_rng(0)
    flagged, stats = 0, []
    for _ in range(splits):
        idx = rng.permutation(len(views))
        halves = [idx[:7], idx[7:]]
        lenses = [lens_from_solution(solve_intrinsics([views[i][0] for i in h], [views[i][1] for i in h],
                                                      (640, 480), "k1k2")) for h in halves]
        r = projection_diff(*lenses)
        assert r.raw.test is not None
        flagged += bool(r.significant)
        stats.append(r.raw.test.statistic)
    print(f"opencv-left-right left, random 7 + 6 splits: {flagged} / {splits} flagged; chi2 median "
          f"{np.median(stats):.1f}, quartiles {np.percentile(stats, 25):.1f} / {np.percentile(stats, 75):.1f} "
          f"(5 dof: median 4.35 if the covariances were honest)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=100)
    parser.add_argument("--splits", type=int, default=40)
    args = parser.parse_args()
    print(f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, load {os.getloadavg()[0]:.1f}")
    t = time.perf_counter()
    corner_rates(args.pairs)
    real_splits(args.splits)
    print(f"{time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()
