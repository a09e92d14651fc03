"""Rig baseline and rotation sigmas (Jacobian, frame-level, reported) against a bootstrap over frames.

Real pairs (shared datasets): each camera's photos detected once by calibctl's detector; the bootstrap draws
the
frame keys with replacement (a frame: the photos of one key, paired or not), re-calibrates each member on its
drawn photos (k1k2, as ``rig solve-folders``) and re-solves the rig; sd over the resamples.
Renders: 2-camera 75 mm rigs rendered and detected (tests/core/rig_sessions), members calibrated on their own
rendered views, z = (est - true) / sigma over seeds.

    python benchmarks/bench_rig_sigma.py [--resamples 100] [--seeds 30] [--only real|renders]
"""

from __future__ import annotations

import argparse
import datetime
import os
import pickle
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import cv2  # noqa: E402
from machine import cpu_model  # noqa: E402  (benchmarks/machine.py)

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.board.views import BoardView  # noqa: E402
from calibctl.core.capture.image_outcomes import classify_session  # noqa: E402
from calibctl.core.extrinsics.rig_problem import RigViews  # noqa: E402
from calibctl.core.extrinsics.rig_solve import solve_rig  # noqa: E402
from calibctl.core.extrinsics.rig_tree import sigma_rotation_deg, sigma_translation_mm  # noqa: E402
from calibctl.core.extrinsics.se3 import rotation_angle_deg  # noqa: E402
from calibctl.errors import CalibctlError  # noqa: E402
from calibctl.workflows.rig.rig_folders import calibrate_member  # noqa: E402

DATA = Path("/work/shared/datasets")
REAL = {
    "opencv-left-right": (BoardSpec.chessboard(9, 6, 0.025), "left*.jpg", "right*.jpg"),
    "baka-stereo": (BoardSpec.chessboard(7, 10, 0.023), "left/left_*.jpg", "right/right_*.jpg"),
}


def _key(name: str) -> str:
    return "".join(ch for ch in Path(name).stem if ch.isdigit())


def detect(name: str) -> tuple[BoardSpec, dict[str, dict[str, BoardView]], tuple[int, int]]:
    spec, *globs = REAL[name]
    per_cam: dict[str, dict[str, BoardView]] = {}
    size = (0, 0)
    for cam, pattern in zip(("left", "right"), globs, strict=True):
        paths = sorted(str(p) for p in (DATA / name).glob(pattern))
        out = classify_session(paths, spec)
        per_cam[cam] = {
            _key(o.path): BoardView(Path(o.path).name, o.corner_ids, o.corners_px)
            for o in out
            if o.accepted and o.corners_px is not None
        }
        size = next(o.image_size for o in out if o.image_size)
    return spec, per_cam, size


def solve(spec, per_cam, size, keys, names=True):
    members = []
    for cam, views in per_cam.items():
        vs = [views[k] for k in keys if k in views]
        members.append(
            calibrate_member(
                cam,
                [spec.object_points()[v.corner_ids] for v in vs],
                [v.corners_px for v in vs],
                size,
                "k1k2",
                [v.name for v in vs] if names else None,
            )[0]
        )
    rows = tuple((per_cam["left"].get(k), per_cam["right"].get(k)) for k in keys)
    views = RigViews(("left", "right"), spec.object_points(), tuple(f"{i}" for i in range(len(keys))), rows)
    return solve_rig(views, members)


def numbers(sol):
    T = sol.T_a_b(1, 0)
    out = {
        "baseline_mm": float(np.linalg.norm(T[:3, 3]) * 1e3),
        "rotation_deg": rotation_angle_deg(T[:3, :3]),
    }
    for tag, jac in (("", False), ("jac_", True)):
        cov = sol.pair_covariance(1, 0, jacobian=jac)
        out[f"{tag}sigma_baseline_mm"] = sigma_translation_mm(cov, T[:3, 3])
        out[f"{tag}sigma_rotation_deg"] = sigma_rotation_deg(cov)
    return out


def real(name: str, resamples: int) -> None:
    spec, per_cam, size = detect(name)
    keys = sorted(set(per_cam["left"]) | set(per_cam["right"]))
    try:
        full = numbers(solve(spec, per_cam, size, keys))
    except CalibctlError as exc:  # a set that is no rig (baka-stereo: webcams not synchronised) has no sigma
        print(f"{name}: {len(keys)} frame keys; the rig solve refuses it: {exc.message[:240]}")
        return
    rng = np.random.default_rng(0)
    boot = []
    for _ in range(resamples):
        draw = [keys[i] for i in rng.integers(0, len(keys), len(keys))]
        try:
            boot.append(numbers(solve(spec, per_cam, size, draw, names=False)))
        except Exception as exc:  # noqa: BLE001 - a degenerate resample is skipped and counted
            print(f"  resample skipped: {exc}")
    b = np.array([[n["baseline_mm"], n["rotation_deg"]] for n in boot])
    sd = b.std(axis=0, ddof=1)
    print(
        f"{name}: {len(keys)} frame keys, {len(boot)} resamples; baseline {full['baseline_mm']:.3f} mm, "
        f"rotation {full['rotation_deg']:.3f} deg"
    )
    print(
        f"  baseline sigma jacobian {full['jac_sigma_baseline_mm']:.4f} reported "
        f"{full['sigma_baseline_mm']:.4f} "
        f"bootstrap sd {sd[0]:.4f} -> sd/reported {sd[0] / full['sigma_baseline_mm']:.2f} "
        f"(sd/jacobian {sd[0] / full['jac_sigma_baseline_mm']:.2f})"
    )
    print(
        f"  rotation sigma jacobian {full['jac_sigma_rotation_deg']:.4f} reported "
        f"{full['sigma_rotation_deg']:.4f} "
        f"bootstrap sd {sd[1]:.4f} -> sd/reported {sd[1] / full['sigma_rotation_deg']:.2f} "
        f"(sd/jacobian {sd[1] / full['jac_sigma_rotation_deg']:.2f})"
    )


def _z_at(sol, truth, threshold: float) -> tuple[float, float]:
    """(z, reported / jacobian baseline sigma) with the frame-level sigma used only above ``threshold``."""
    f = np.ones(sol.jacobian_covariance.shape[0])
    if sol.frame_factors is not None:
        f = np.where(sol.frame_factors > threshold, sol.frame_factors, 1.0)
    cov = sol.jacobian_covariance * np.outer(f, f)
    variant = replace(sol, covariance=cov)
    T = sol.T_a_b(1, 0)
    sigma = sigma_translation_mm(variant.pair_covariance(1, 0), T[:3, 3])
    err = float(np.linalg.norm(T[:3, 3]) * 1e3 - np.linalg.norm(truth.T_root_cam[1][:3, 3]) * 1e3)
    return err / sigma, sigma / sigma_translation_mm(sol.pair_covariance(1, 0, jacobian=True), T[:3, 3])


def renders(seeds: int) -> None:
    from tests.core.rig_sessions import BOARD, rendered_session

    cache = Path("/tmp/bench_rig_sigma_renders.pkl")  # rendering is the slow part; the solves are not
    sessions = pickle.loads(cache.read_bytes()) if cache.exists() else {}
    sols = []
    for seed in range(seeds):
        if seed not in sessions:
            sessions[seed] = rendered_session(2, seed=7500 + seed, n_frames=14, baselines_m=(0.075,))
            cache.write_bytes(pickle.dumps(sessions))
        truth, views = sessions[seed]
        per_cam = {
            cam: {
                f"{f}": BoardView(f"{cam}{f}", row[c].corner_ids, row[c].corners_px)
                for f, row in enumerate(views.views)
                if row[c] is not None
            }
            for c, cam in enumerate(("left", "right"))
        }  # unique photo names, as real folders have
        keys = sorted(set(per_cam["left"]) | set(per_cam["right"]), key=int)
        sols.append((solve(BOARD, per_cam, truth.cameras[0].image_size, keys), truth))
    for threshold in (1.0, 1.3, 1.5):
        zs = np.array([_z_at(sol, truth, threshold) for sol, truth in sols])
        zj = np.array([_z_at(sol, truth, np.inf)[0] for sol, truth in sols])
        print(
            f"renders: {seeds} seeds, frame-level used above x{threshold}: baseline z sd "
            f"{zs[:, 0].std(ddof=1):.2f} "
            f"(jacobian alone {zj.std(ddof=1):.2f}), z mean {zs[:, 0].mean():+.2f}; reported / jacobian "
            "sigma "
            f"median {np.median(zs[:, 1]):.2f} max {zs[:, 1].max():.2f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resamples", type=int, default=100)
    ap.add_argument("--seeds", type=int, default=30)
    ap.add_argument("--only", choices=("real", "renders"), default=None)
    args = ap.parse_args()
    print(
        f"# bench_rig_sigma {datetime.date.today()}: {cpu_model()}, {os.cpu_count()} cpus, load "
        f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}; Python {sys.version.split()[0]}, OpenCV "
        f"{cv2.__version__}, numpy {np.__version__}"
    )
    if args.only != "renders":
        for name in REAL:
            real(name, args.resamples)
    if args.only != "real":
        renders(args.seeds)


if __name__ == "__main__":
    main()
