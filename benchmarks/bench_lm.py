"""The shared Levenberg-Marquardt solver (calibctl.core.lm): speed and answers of the solves that use it.

Times, on the same seeded inputs, calibctl's fisheye intrinsics solve (the Schur path: 8 lens parameters
+ 6 per view), the joint rig LM (the dense path: 3 and 4 pinhole cameras, optionally with intrinsics
refined), the rig's held-out validation (a rig solve per fold, then each held-out frame's board pose) and
the one-view fisheye pose refinement, and saves every answer to an .npz, so that two
checkouts (before and after a solver change) can be compared number for number:

    PYTHONPATH=<tree A> python <tree B>/benchmarks/bench_lm.py --out a.npz
    PYTHONPATH=<tree B> python <tree B>/benchmarks/bench_lm.py --out b.npz --compare a.npz

Inputs: fisheye sessions as bench_fisheye.py (1280x960, 150/170/190 deg, 15-20 views of a 9 x 6 board,
0.2 px noise, seeds 0..N-1); rigs from calibctl.core.synth.rig (640x480, 20 frames, 0.2 px noise).
Reported: the best of ``--repeats`` wall times per input (single-threaded OpenCV, as the solves run), and
with ``--compare`` the largest difference of any answer relative to that answer's largest element.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_validation import validate_rig_holdout
from calibctl.core.intrinsics.fisheye_model import fisheye_pose, refine_fisheye_pose
from calibctl.core.intrinsics.solve import forget_recent_solves, solve_intrinsics
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session
from calibctl.core.synth.rig import rig_corners, synthesize_rig

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model  # noqa: E402

SIZE = (1280, 960)
LENSES = ((150.0, True), (170.0, False), (190.0, True), (150.0, False), (170.0, True), (190.0, True))
BOARD = BoardSpec.chessboard(9, 6, 0.025)


def _best(fn: Callable[[], dict[str, np.ndarray]], repeats: int) -> tuple[float, dict[str, np.ndarray]]:
    times, out = [], {}
    for _ in range(repeats):
        forget_recent_solves()  # every repeat computes: a remembered solve would time a digest
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def fisheye_cases(n: int) -> list[tuple[str, Callable[[], dict[str, np.ndarray]]]]:
    cases: list[tuple[str, Callable[[], dict[str, np.ndarray]]]] = []
    for i in range(n):
        fov, circular = LENSES[i % len(LENSES)]
        s = synthesize_fisheye_session(
            FisheyeCamera.from_fov(SIZE, fov, circular), 15 + i % 6, seed=i, noise_px=0.2
        )

        def run(s=s) -> dict[str, np.ndarray]:
            sol = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "fisheye")
            return {
                "K": sol.camera_matrix,
                "D": sol.dist_coeffs,
                "rvecs": sol.rvecs,
                "tvecs": sol.tvecs,
                "rms": np.array(sol.rms_px),
                "sigma": np.array(list(sol.sigma.values())),
            }

        cases.append((f"fisheye seed {i} ({fov:.0f} deg, {len(s.image_points_per_view)} views)", run))
    return cases


def fisheye_pose_cases(n: int) -> list[tuple[str, Callable[[], dict[str, np.ndarray]]]]:
    cases: list[tuple[str, Callable[[], dict[str, np.ndarray]]]] = []
    for i in range(n):
        fov, circular = LENSES[i % len(LENSES)]
        cam = FisheyeCamera.from_fov(SIZE, fov, circular)
        s = synthesize_fisheye_session(cam, 15 + i % 6, seed=i, noise_px=0.2)
        D = np.asarray(s.dist_coeffs, np.float64)

        def run(s=s, cam=cam, D=D) -> dict[str, np.ndarray]:
            out = []
            for o, p in zip(s.object_points_per_view, s.image_points_per_view, strict=True):
                o, p = np.asarray(o, np.float64).reshape(-1, 3), np.asarray(p, np.float64).reshape(-1, 2)
                start = fisheye_pose(o, p, cam.K, D)
                assert start is not None
                out.append(np.concatenate(refine_fisheye_pose(o, p, cam.K, D, *start)))
            return {"poses": np.array(out)}

        cases.append((f"fisheye pose x{len(s.image_points_per_view)} seed {i}", run))
    return cases


def rig_inputs() -> list[tuple[str, RigViews, list[MemberIntrinsics], bool]]:
    """(name, views, true members, refine_intrinsics) of the seeded rigs."""
    out = []
    for n_cams, seed, refine in ((3, 1, False), (4, 2, False), (3, 3, True)):
        rng = np.random.default_rng(seed)
        truth = synthesize_rig(n_cams, BOARD, 20, rng)
        corners = rig_corners(truth, BOARD, 0.2, rng)
        ids = np.arange(BOARD.n_corners)
        rows = tuple(
            tuple(BoardView(f"f{f}", ids, c) if c is not None else None for c in row)
            for f, row in enumerate(corners)
        )
        views = RigViews(
            truth.names, BOARD.object_points(), tuple(f"f{f}" for f in range(len(corners))), rows
        )
        members = [
            MemberIntrinsics(nm, c.K, c.dist, c.image_size)
            for nm, c in zip(truth.names, truth.cameras, strict=True)
        ]
        out.append((f"{n_cams} cams seed {seed}{' refine' if refine else ''}", views, members, refine))
    return out


def rig_cases() -> list[tuple[str, Callable[[], dict[str, np.ndarray]]]]:
    cases: list[tuple[str, Callable[[], dict[str, np.ndarray]]]] = []
    for name, views, members, refine in rig_inputs():

        def run(views=views, members=members, refine=refine) -> dict[str, np.ndarray]:
            sol = solve_rig(views, members, refine_intrinsics=refine, solver="lm")
            return {
                "cam": sol.cam_poses,
                "board": sol.board_poses,
                "cov": sol.covariance,
                "K": np.array([m.camera_matrix for m in sol.members]),
            }

        cases.append((f"rig {name}", run))
        if name == "3 cams seed 1":

            def holdout(views=views, members=members) -> dict[str, np.ndarray]:
                out = validate_rig_holdout(views, members, solver="lm")
                return {
                    "rms": np.array(out.camera_rms_px),
                    "pairs": np.array([[p.epipolar_rms_px, p.rectified_rms_px] for p in out.pairs]),
                }

            cases.append((f"rig {name} held-out (rig solves + board poses)", holdout))
    return cases


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fisheye", type=int, default=6, help="fisheye sessions (seeds 0..N-1)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--out",
        default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "out", "bench_lm.npz"),
        help=".npz to save every answer in (default benchmarks/out/bench_lm.npz)",
    )
    parser.add_argument("--compare", help=".npz of another checkout's answers")
    args = parser.parse_args()
    print(
        f"machine: {cpu_model()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}, Python "
        f"{platform.python_version()}, OpenCV {cv2.__version__}"
    )
    saved: dict[str, np.ndarray] = {}
    other = dict(np.load(args.compare)) if args.compare else {}
    print(f"| input | best of {args.repeats}, ms | max relative difference |\n|---|---|---|")
    for name, fn in fisheye_cases(args.fisheye) + fisheye_pose_cases(args.fisheye) + rig_cases():
        seconds, out = _best(fn, args.repeats)
        diffs = []
        for key, value in out.items():
            saved[f"{name}/{key}"] = np.asarray(value, np.float64)
            ref = other.get(f"{name}/{key}")
            if ref is not None:
                diffs.append(
                    float(np.max(np.abs(np.asarray(value) - ref)) / max(float(np.max(np.abs(ref))), 1e-300))
                )
        diff = f"{max(diffs):.1e}" if diffs else "-"
        saved[f"{name}/ms"] = np.array(1000 * seconds)
        ref_ms = other.get(f"{name}/ms")
        was = f" (was {float(ref_ms):.1f})" if ref_ms is not None else ""
        print(f"| {name} | {1000 * seconds:.1f}{was} | {diff} |")
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    np.savez(args.out, **saved)  # type: ignore[arg-type]
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
