"""`calibctl check` statistics: false-fail rate on unchanged cameras, detection of a 0.5 % focal change and
of a 2 px principal-point shift from 10 views, and the check's compute time against a solve's.

Reference calibrations: the seed's camera (calibctl synth's lens, 640x480), "good" scenario poses, 20 views,
solved with the production model (k1k2) plus calibctl's held-out validation (what `calibctl solve`
stores). Check sessions: 10 fresh "good" views of the SAME camera (unchanged), or of the camera with
fx and fy x1.005, or with cx + 2 px, checked with calibctl.core.check.recheck against the reference.

Two sources of corners:
  --mode renders: rendered board photos (calibctl.core.synth.pinhole, random photometry per view) detected by
      calibctl's detector - the real pipeline; sessions cached in benchmarks/out/check-sessions/.
  --mode corners: projected corners plus Gaussian noise (--noise-px per coordinate, default 0.03, what
      the renders leave: measured below), fast enough for thousands of sessions.
Beside it, the plain-OpenCV way to re-test (solvePnP with the stored K + RMS compared with a fixed 1.1x
of the held-out RMS), on the same sessions.

Run: python benchmarks/bench_check.py [--mode renders|corners] [--sessions 200] [--refs 5] [--cases
unchanged,...]
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model  # noqa: E402

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.capture.detect import detect_board  # noqa: E402
from calibctl.core.check.recheck import Reference, recheck  # noqa: E402
from calibctl.core.intrinsics.solve import solve_intrinsics  # noqa: E402
from calibctl.core.intrinsics.validation import validate_holdout  # noqa: E402
from calibctl.core.synth.pinhole import Photometry, PinholeCamera, render_background, render_view  # noqa: E402
from calibctl.core.synth.scenes import _cell_targets, _sample_pose, default_distance_range_m, scenario_poses  # noqa: E402

BOARD = BoardSpec.chessboard(9, 6, 0.025)
SIZE = (640, 480)
REF_VIEWS, CHECK_VIEWS = 20, 10
CACHE = Path(__file__).resolve().parent / "out" / "check-sessions"
CASES = {"unchanged": (1.0, 0.0), "focal +0.5 %": (1.005, 0.0), "cx +2 px": (1.0, 2.0)}

Views = tuple[list[np.ndarray], list[np.ndarray]]


def camera_for(case: str) -> PinholeCamera:
    base = PinholeCamera.seed_reference(SIZE)
    scale, dcx = CASES[case]
    K = base.K.copy()
    K[0, 0] *= scale
    K[1, 1] *= scale
    K[0, 2] += dcx
    return PinholeCamera(K, base.dist.copy(), SIZE)


def near_poses(camera: PinholeCamera, n_views: int, rng: np.random.Generator) -> list[np.ndarray]:
    """The check protocol's views: the board close (85-100 % of the width), tilted 20-35 deg, directions
    around."""
    near = default_distance_range_m(camera, BOARD, (0.85, 1.0))
    targets = _cell_targets(camera, n_views)
    return [
        _sample_pose(
            camera,
            BOARD,
            rng,
            targets[i],
            np.deg2rad(rng.uniform(20.0, 35.0)),
            2 * np.pi * i / 8 + rng.uniform(-0.2, 0.2),
            near,
        )
        for i in range(n_views)
    ]


def session(
    case: str, seed: int, n_views: int, mode: str, noise_px: float, poses_kind: str = "good"
) -> Views:
    camera = camera_for(case)
    rng = np.random.default_rng(seed)
    poses = (
        scenario_poses("good", camera, BOARD, n_views, rng)
        if poses_kind == "good"
        else near_poses(camera, n_views, rng)
    )
    if mode == "corners":
        obj = BOARD.object_points()
        img = []
        for T in poses:
            rvec, _ = cv2.Rodrigues(T[:3, :3])
            proj, _ = cv2.projectPoints(obj, rvec, T[:3, 3], camera.K, camera.dist)
            img.append(proj.reshape(-1, 2) + rng.normal(0.0, noise_px, (len(obj), 2)))
        return [obj] * len(img), img
    path = CACHE / f"{case.split()[0]}-{n_views}-{seed}{'' if poses_kind == 'good' else '-' + poses_kind}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    background = render_background(SIZE, rng)
    objs, imgs = [], []
    for T in poses:
        det, _ = detect_board(render_view(camera, BOARD, T, rng, Photometry.random(rng), background), BOARD)
        if det is not None:
            objs.append(BOARD.object_points()[det.corner_ids])
            imgs.append(det.corners_px)
    CACHE.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps((objs, imgs)))
    return objs, imgs


def reference(
    seed: int, mode: str, noise_px: float, n_views: int = REF_VIEWS
) -> tuple[np.ndarray, np.ndarray, Reference, dict, float]:
    obj, img = session("unchanged", seed, n_views, mode, noise_px)
    t0 = time.perf_counter()
    fit = solve_intrinsics(obj, img, SIZE, "k1k2")
    rep = validate_holdout(obj, img, SIZE, "k1k2", fit=fit)
    solve_s = time.perf_counter() - t0
    h = rep.holdout
    ref = Reference(
        rep.holdout_rms_px,
        sum(len(p) for p in img),
        len(img),
        h.radius_edges_px,
        h.ring_rms_px,
        h.ring_counts,
        h.octant_rms_px,
        h.octant_counts,
    )
    sigma = {"focal": fit.sigma["fx"] / fit.camera_matrix[0, 0], "cx": fit.sigma["cx"], "cy": fit.sigma["cy"]}
    return fit.camera_matrix, fit.dist_coeffs, ref, sigma, solve_s


def plain_fails(
    obj: list[np.ndarray], img: list[np.ndarray], K: np.ndarray, D: np.ndarray, ref_rms: float
) -> bool:
    """The plain OpenCV re-test: solvePnP with the stored model, overall RMS above 1.1x the held-out RMS."""
    sq, n = 0.0, 0
    for o, i in zip(obj, img, strict=True):
        _, rvec, tvec = cv2.solvePnP(o, i, K, D)
        proj, _ = cv2.projectPoints(o, rvec, tvec, K, D)
        sq += float(np.sum((i - proj.reshape(-1, 2)) ** 2))
        n += len(i)
    return float(np.sqrt(sq / n)) > 1.1 * ref_rms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=("renders", "corners"), default="corners")
    parser.add_argument("--sessions", type=int, default=200, help="check sessions per case")
    parser.add_argument(
        "--refs", type=int, default=5, help="reference calibrations the sessions are spread over"
    )
    parser.add_argument("--noise-px", type=float, default=0.03)
    parser.add_argument(
        "--ref-views", type=int, default=REF_VIEWS, help="views of each reference calibration"
    )
    parser.add_argument(
        "--check-poses",
        choices=("good", "near"),
        default="good",
        help="check views: the solve's 'good' scenario, or the check protocol's near tilted views",
    )
    parser.add_argument(
        "--cases", default=",".join(CASES), help=f"comma-separated subset of: {', '.join(CASES)}"
    )
    args = parser.parse_args()
    refs = [reference(10_000 + r, args.mode, args.noise_px, args.ref_views) for r in range(args.refs)]
    print(
        f"# bench_check {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, load "
        f"{os.getloadavg()[0]:.1f}, "
        f"mode {args.mode}, {args.ref_views}-view references, check poses {args.check_poses}"
        + (f" (noise {args.noise_px} px)" if args.mode == "corners" else "")
    )
    print(
        f"reference held-out RMS {np.mean([r[2].rms_px for r in refs]):.4f} px (mean of {args.refs}), "
        f"solve + held-out {np.median([r[4] for r in refs]) * 1000:.0f} ms median"
    )
    print(
        "| case | sessions | calibctl check fails | plain OpenCV (RMS > 1.1x held-out) fails | check time "
        "(median) |"
    )
    print("|---|---|---|---|---|")
    for case in args.cases.split(","):
        fails = plain = 0
        times = []
        for i in range(args.sessions):
            K, D, ref, sigma, _ = refs[i % args.refs]
            obj, img = session(
                case,
                20_000 + 1000 * list(CASES).index(case) + i,
                CHECK_VIEWS,
                args.mode,
                args.noise_px,
                args.check_poses,
            )
            t0 = time.perf_counter()
            result = recheck(obj, img, K, D, SIZE, ref, sigma)
            times.append(time.perf_counter() - t0)
            fails += not result.passed
            plain += plain_fails(obj, img, K, D, ref.rms_px)
        n = args.sessions
        print(
            f"| {case} | {n} | {fails} ({100 * fails / n:.1f} %) | {plain} ({100 * plain / n:.1f} %) | "
            f"{np.median(times) * 1000:.1f} ms |",
            flush=True,
        )


if __name__ == "__main__":
    main()
