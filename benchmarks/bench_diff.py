"""`calibctl diff`'s error rates (docs/diff.md): how often an unchanged camera is flagged, how often a 0.3 %
focal change or a 1 px principal-point shift is caught, on seeded corner-level sessions and on real photos.

Corners: tests/core/compare/sessions.py (the seed's focal length and k1, k2 at 640x480, 30 views, 0.03 px
noise, solved k1k2); "misfit" solves the seed's full 5-term lens (p1 p2 k3 too) with the k1k2 model, so
each solve's model error depends on its views. Real: opencv-left-right's 13 left photos detected by
calibctl's detector, split at random into 7 + 6 views, each half solved k1k2 and diffed; baka-stereo's left
camera from its odd and its even frames, and left against right (all detected photos, k1k2).

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
from tests.datasets import BAKA_STEREO, LEFT_RIGHT  # noqa: E402


def corner_rates(pairs: int) -> None:
    full = np.array(PinholeCamera.seed_reference(SIZE).dist, dtype=np.float64)
    cases = [
        ("unchanged", true_K(), None),
        ("focal +0.3 %", true_K(focal_scale=1.003), None),
        ("cx +1 px", true_K(dcx_px=1.0), None),
        ("unchanged, k1k2 misfit", true_K(), full),
        ("focal +0.3 %, k1k2 misfit", true_K(focal_scale=1.003), full),
        ("cx +1 px, k1k2 misfit", true_K(dcx_px=1.0), full),
    ]
    print("| case | flagged | median chi2 (dof) |\n|---|---|---|")
    for name, K_b, dist in cases:
        kw = {} if dist is None else {"dist": dist}
        flagged, stats, dof = 0, [], 0
        for i in range(pairs):
            r = projection_diff(
                lens_from_solution(solve(true_K(), 1000 + i, **kw)),
                lens_from_solution(solve(K_b, 50_000 + i, **kw)),
            )
            flagged += bool(r.significant)
            assert r.raw.test is not None
            stats.append(r.raw.test.statistic)
            dof = r.raw.test.dof
        print(
            f"| {name} | {flagged} / {pairs} ({100 * flagged / pairs:.1f} %) | {np.median(stats):.1f} "
            f"({dof}) |",
            flush=True,
        )


def detected(paths: list, spec: BoardSpec) -> list[tuple[np.ndarray, np.ndarray]]:
    """(model points, corners) of every photo calibctl's detector finds the board in."""
    obj_all = spec.object_points()
    views = []
    for path in paths:
        det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), spec)
        if det is not None:
            views.append((obj_all[det.corner_ids], det.corners_px))
    return views


def lens_of(views: list, size: tuple[int, int]):
    return lens_from_solution(solve_intrinsics([v[0] for v in views], [v[1] for v in views], size, "k1k2"))


def baka(size: tuple[int, int] = (1280, 720)) -> None:
    spec = BoardSpec.chessboard(7, 10, 0.023)
    left = detected(sorted((BAKA_STEREO / "left").glob("*.jpg")), spec)
    right = detected(sorted((BAKA_STEREO / "right").glob("*.jpg")), spec)
    for name, a, b in (("left odd vs even frames", left[0::2], left[1::2]), ("left vs right", left, right)):
        r = projection_diff(lens_of(a, size), lens_of(b, size))
        assert r.raw.test is not None and r.fit.test is not None
        print(
            f"baka-stereo {name} ({len(a)} and {len(b)} views): {'different' if r.significant else 'same'}; "
            f"chi2 {r.raw.test.statistic:.1f} / {r.fit.test.statistic:.1f} vs {r.raw.test.threshold:.1f} "
            f"({r.raw.test.dof} dof); |d| p50 {r.raw.percentiles_px['p50']:.2f} px as stored, "
            f"{r.fit.percentiles_px['p50']:.2f} px after {r.rotation_fit_deg:.3f} deg",
            flush=True,
        )


def real_splits(splits: int) -> None:
    views = detected(sorted(LEFT_RIGHT.glob("left*.jpg")), BoardSpec.chessboard(9, 6, 0.025))
    rng = np.random.default_rng(0)
    flagged, stats = 0, []
    for _ in range(splits):
        idx = rng.permutation(len(views))
        halves = [idx[:7], idx[7:]]
        lenses = [
            lens_from_solution(
                solve_intrinsics([views[i][0] for i in h], [views[i][1] for i in h], (640, 480), "k1k2")
            )
            for h in halves
        ]
        r = projection_diff(*lenses)
        assert r.raw.test is not None
        flagged += bool(r.significant)
        stats.append(r.raw.test.statistic)
    print(
        f"opencv-left-right left, random 7 + 6 splits: {flagged} / {splits} flagged; chi2 median "
        f"{np.median(stats):.1f}, quartiles {np.percentile(stats, 25):.1f} / {np.percentile(stats, 75):.1f} "
        f"(5 dof: median 4.35 if the covariances were honest)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=100)
    parser.add_argument("--splits", type=int, default=40)
    args = parser.parse_args()
    print(f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, load {os.getloadavg()[0]:.1f}")
    t = time.perf_counter()
    if args.pairs:
        corner_rates(args.pairs)
    if args.splits:
        real_splits(args.splits)
    baka()
    print(f"{time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()
