"""Loop closure: Mahalanobis distances of clean rendered 3- and 4-camera rigs (false alarms) and of broken
loops.

Clean: rigs rendered and detected by calibctl's detector (tests/core/rig_sessions.rendered_session, 12 frames,
every frame seen by >= 3 cameras), the true intrinsics held fixed; every simple cycle of every seed. Under a
right covariance d^2 follows chi-square with 6 dof (mean 6; 99.7 % quantile 20.1, d = 4.48).
Broken: corner-level 3-camera rigs (0.2 px iid noise, as tests/core/extrinsics/test_rig_solve.py) and rendered
3-camera rigs with frames seen by two cameras, camera 2's corners of the frames it shares with camera 0 only
shifted by ``--shifts`` px: pair 0-2 then disagrees with 0-1-2.
Each loop is judged by four covariances: the pairs as independent (Jacobian blocks, the old rule),
the joint Jacobian one (the rule's, core.extrinsics.rig_loop), the joint frame-level one, and the Jacobian one
scaled by max(1, tr(Cov_jac^-1 Cov_frame) / 6) (a frame-level factor, not used).

    python benchmarks/bench_rig_loop.py [--seeds 30] [--shifts 3 2 1 0.5]
"""

from __future__ import annotations

import argparse
import datetime
import pickle
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from machine import cpu_model  # noqa: E402  (benchmarks/machine.py)

from calibctl.core.extrinsics.rig_loop import loop_covariance  # noqa: E402
from calibctl.core.extrinsics.rig_problem import RigViews  # noqa: E402
from calibctl.core.extrinsics.rig_tree import T_to_pose, pose_to_T, propagate, simple_cycles  # noqa: E402
from calibctl.core.extrinsics.rig_validation import pairwise_solutions  # noqa: E402
from calibctl.core.extrinsics.se3 import invert  # noqa: E402
from tests.core.rig_sessions import corner_session, rendered_session, true_members  # noqa: E402

LIMIT = 4.48
CACHE = Path("/tmp/bench_rig_loop_cache")
KINDS = ("independent", "joint Jacobian", "joint frame-level", "joint Jacobian x frame factor")


def distances(views: RigViews, members) -> list[dict[str, float]]:
    """Per cycle, d under each covariance of KINDS."""
    pairs = pairwise_solutions(views, members)
    out = []
    for cycle in simple_cycles(range(len(views.cameras)), {frozenset(p) for p in pairs}):
        hops = list(zip(cycle, (*cycle[1:], cycle[0]), strict=True))
        sols = [pairs[(min(a, b), max(a, b))] for a, b in hops]
        x = np.concatenate([s.cam_poses[1] for s in sols])
        fwd = [a < b for a, b in hops]

        def around(v, fwd=fwd):
            T = np.eye(4)
            for p, f in zip(np.split(v, len(fwd)), fwd, strict=True):
                T = T @ (invert(pose_to_T(p)) if f else pose_to_T(p))
            return T_to_pose(T)

        r = around(x)
        cov = loop_covariance(sols, views, around, x)
        block = np.zeros((x.size, x.size))
        for i, s in enumerate(sols):
            block[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = (
                s.jacobian_covariance if s.jacobian_covariance is not None else s.covariance
            )
        covs = {
            "independent": propagate(around, x, block),
            "joint Jacobian": cov.jacobian,
            "joint frame-level": cov.frame_level,
            "joint Jacobian x frame factor": None
            if cov.frame_level is None
            else cov.jacobian * max(1.0, np.trace(np.linalg.solve(cov.jacobian, cov.frame_level)) / 6),
        }
        out.append(
            {
                k: (float(np.sqrt(r @ np.linalg.solve(c, r))) if c is not None else float("nan"))
                for k, c in covs.items()
            }
        )
    return out


def cached(name: str, make):
    CACHE.mkdir(exist_ok=True)
    path = CACHE / f"{name}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    value = make()
    path.write_bytes(pickle.dumps(value))
    return value


def breakable(views: RigViews) -> bool:
    """Whether some frame is seen by cameras 0 and 2 but not 1 (what ``broken`` shifts)."""
    return any(row[2] is not None and row[1] is None and row[0] is not None for row in views.views)


def broken(views: RigViews, shift_px: float) -> RigViews:
    rows = [list(r) for r in views.views]
    for row in rows:
        if row[2] is not None and row[1] is None and row[0] is not None:
            row[2] = type(row[2])(row[2].name, row[2].corner_ids, row[2].corners_px + [shift_px, 0.0])
    return RigViews(views.cameras, views.model_points_m, views.frames, tuple(tuple(r) for r in rows))


def summary(label: str, ds: list[dict[str, float]]) -> None:
    for k in KINDS:
        d = np.array([x[k] for x in ds])
        d = d[np.isfinite(d)]
        if d.size == 0:
            continue
        print(
            f"| {label} | {k} | {d.size} | {np.mean(d**2):.2f} | {np.median(d):.2f} | {np.max(d):.2f} | "
            f"{np.mean(d > LIMIT):.3f} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=30)
    ap.add_argument("--shifts", type=float, nargs="*", default=[3.0, 2.0, 1.0, 0.5])
    args = ap.parse_args()
    print(f"# bench_rig_loop {datetime.date.today()} on {cpu_model()}")
    print("| data | covariance | loops | mean d^2 (chi2 6: 6) | median d | max d | share d > 4.48 |")
    print("|---|---|---|---|---|---|---|")
    for n in (3, 4):
        ds = []
        for seed in range(args.seeds):
            truth, views = cached(
                f"r{n}_{seed}",
                lambda n=n, seed=seed: rendered_session(
                    n, seed=3000 + 100 * n + seed, n_frames=12, min_cameras=3
                ),
            )
            ds += distances(views, true_members(truth))
        summary(f"clean renders, {n} cameras", ds)
    corner = [corner_session(3, seed=2300 + s) for s in range(args.seeds)]
    summary("clean corner-level, 3 cameras", [d for t, v in corner for d in distances(v, true_members(t))])
    renders = [
        cached(f"b3_{s}", lambda s=s: rendered_session(3, seed=5300 + s, n_frames=16))
        for s in range(args.seeds)
    ]
    summary(
        "clean renders with pair-only frames, 3 cameras",
        [d for t, v in renders for d in distances(v, true_members(t))],
    )
    # broken: only the seeds with frames to shift, and only the loop 0-1-2 (a 3-camera rig has no other)
    corner = [(t, v) for t, v in corner if breakable(v)]
    renders = [(t, v) for t, v in renders if breakable(v)]
    for shift in args.shifts:
        summary(
            f"broken {shift:g} px, corner-level ({len(corner)} seeds)",
            [d for t, v in corner for d in distances(broken(v, shift), true_members(t))],
        )
        summary(
            f"broken {shift:g} px, renders ({len(renders)} seeds)",
            [d for t, v in renders for d in distances(broken(v, shift), true_members(t))],
        )


if __name__ == "__main__":
    main()
