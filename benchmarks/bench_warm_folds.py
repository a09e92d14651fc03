"""Folds started from the fit against folds started cold: LM iterations, CPU, and whether they land together.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_warm_folds.py [--sessions 8] [--views 20]

A held-out fold (and a side of the camera-change test) solves most of a session's views again. Cold, OpenCV
starts it from its closed-form K (homographies) and zero distortion; warm, from the whole session's K and
distortion (``solve_intrinsics(initial=, initial_dist=)``, CALIB_USE_INTRINSIC_GUESS). Per model, on
``--sessions`` synthetic sessions (core.synth.corners, 1280x960, the seed's lens, 0.2 px corner noise), each
session's 5 folds (``validation.fold_assignment``) are solved both ways with OpenCV on one thread:

  * LM iterations: the fewest ``TermCriteria`` counts (EPS DBL_EPSILON, up to 100) whose K and distortion
    equal those of OpenCV's own criteria to the bit, i.e. the iterations OpenCV's LM ran before it stopped;
    "warm, stopped": the same for the warm start under the relative step calibctl stops a warm start at
    (``solution.WARM_STEP_EPS``);
  * CPU: ``time.process_time`` per fold solve (cv2.calibrateCamera, no uncertainty), best of 3;
  * the largest relative difference of a fold's K and held-out RMS, warm (as calibctl solves it: stopped)
    against cold (``validate_holdout`` with and without ``warm``): the same minimum reads ~1e-8; a different
    one reads ~1e-3 or more.
Prints markdown with machine, date and load.
"""

from __future__ import annotations

import argparse
import datetime as dt
import platform
import statistics
import time

import cv2
import numpy as np
from machine import cpu_model, load_1min

from calibctl.core.intrinsics.solution import WARM_CRITERIA, WARM_STEP_EPS
from calibctl.core.intrinsics.solve import check_inputs, get_model, single_threaded_opencv, solve_intrinsics
from calibctl.core.intrinsics.validation import fold_assignment, validate_holdout
from calibctl.core.synth.corners import synthesize_session

K_TRUE = np.array([[1600.0, 0.0, 639.5], [0.0, 1600.0, 479.5], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.2814, 0.0977, 0.0001, -0.0002, -0.0163])
SIZE = (1280, 960)
MODELS = ("k1k2", "k1k2k3", "k1k2p1p2k3", "opencv-default", "rational")
MAX_COUNT = WARM_CRITERIA[1]
DBL_EPS = float(np.finfo(float).eps)


def _calibrate(objs, imgs, K0, D0, flags, count=None, eps=None):
    """K, D of cv2.calibrateCamera; OpenCV's own criteria when neither ``count`` nor ``eps`` is given."""
    stop = {}
    if count is not None or eps is not None:
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, count or MAX_COUNT, eps or DBL_EPS)
        stop = {"criteria": criteria}
    _, K, D, _, _ = cv2.calibrateCamera(objs, imgs, SIZE, K0.copy(), D0.copy(), flags=flags, **stop)
    return K, D


def _iterations(objs, imgs, K0, D0, flags, eps=None) -> int:
    """The fewest iteration counts giving the answer of OpenCV's own criteria (``eps`` None) or of
    (MAX_COUNT, ``eps``) bit for bit (binary search: once OpenCV's LM has stopped, more allowed iterations
    change nothing)."""
    K, D = _calibrate(objs, imgs, K0, D0, flags, eps=eps)
    lo, hi = 1, MAX_COUNT
    while lo < hi:
        mid = (lo + hi) // 2
        Km, Dm = _calibrate(objs, imgs, K0, D0, flags, mid, eps)
        if np.array_equal(Km, K) and np.array_equal(Dm, D):
            hi = mid
        else:
            lo = mid + 1
    return lo


def _cpu_s(objs, imgs, K0, D0, flags, eps=None) -> float:
    best = float("inf")
    for _ in range(3):
        t0 = time.process_time()
        _calibrate(objs, imgs, K0, D0, flags, eps=eps)
        best = min(best, time.process_time() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--sessions", type=int, default=8)
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--models", default=",".join(MODELS))
    args = parser.parse_args()
    print(
        f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, Python {platform.python_version()}, "
        f"OpenCV {cv2.__version__}, load {load_1min():.2f} at start; {args.sessions} sessions of "
        f"{args.views} views at {SIZE[0]}x{SIZE[1]}, 5 folds each\n"
    )
    print(
        "| model | LM iterations cold (median, max) | warm (median, max) | warm, stopped (median, max) "
        "| CPU ms a fold cold | warm | warm, stopped | warm stopped / cold "
        "| largest relative difference, warm stopped vs cold |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.models.split(","):
        m = get_model(name)
        it_cold: list[int] = []
        it_warm: list[int] = []
        it_stop: list[int] = []
        cpu_cold: list[float] = []
        cpu_warm: list[float] = []
        cpu_stop: list[float] = []
        worst = 0.0
        for seed in range(args.sessions):
            ses = synthesize_session(K_TRUE, D_TRUE, SIZE, n_views=args.views, seed=seed, noise_px=0.2)
            obj, img = ses.object_points_per_view, ses.image_points_per_view
            fit = solve_intrinsics(obj, img, SIZE, name, uncertainty=False)
            folds = fold_assignment(len(obj), m.min_views)
            cold_start = np.eye(3)
            if m.flags & cv2.CALIB_RATIONAL_MODEL:  # solve_intrinsics' own cold start for rational
                cold_start = np.array(
                    solve_intrinsics(obj, img, SIZE, "k1k2", uncertainty=False).camera_matrix
                )
            cold_flags = m.flags | (
                cv2.CALIB_USE_INTRINSIC_GUESS if m.flags & cv2.CALIB_RATIONAL_MODEL else 0
            )
            warm_flags = m.flags | cv2.CALIB_USE_INTRINSIC_GUESS
            with single_threaded_opencv():
                for f in range(int(folds.max()) + 1):
                    train = np.flatnonzero(folds != f)
                    objs, imgs = check_inputs([obj[i] for i in train], [img[i] for i in train], SIZE, m)
                    cold = (cold_start, np.zeros(m.n_coeffs), cold_flags)
                    warm = (np.array(fit.camera_matrix), np.array(fit.dist_coeffs), warm_flags)
                    it_cold.append(_iterations(objs, imgs, *cold))
                    it_warm.append(_iterations(objs, imgs, *warm))
                    cpu_cold.append(_cpu_s(objs, imgs, *cold))
                    cpu_warm.append(_cpu_s(objs, imgs, *warm))
                    it_stop.append(_iterations(objs, imgs, *warm, WARM_STEP_EPS))
                    cpu_stop.append(_cpu_s(objs, imgs, *warm, WARM_STEP_EPS))
            # what calibctl reports, through validate_holdout (rational ignores warm: solve.starts_warm)
            c = validate_holdout(obj, img, SIZE, name, fit=fit)
            w = validate_holdout(obj, img, SIZE, name, fit=fit, warm=True)
            if m.flags & cv2.CALIB_RATIONAL_MODEL:  # measure the warm start it refuses, fold by fold
                w_K = []
                for f in range(int(folds.max()) + 1):
                    train = np.flatnonzero(folds != f)
                    w_K.append(
                        solve_intrinsics(
                            [obj[i] for i in train],
                            [img[i] for i in train],
                            SIZE,
                            name,
                            fit.camera_matrix,
                            uncertainty=False,
                            initial_dist=fit.dist_coeffs,
                        ).camera_matrix
                    )
                warm_K = np.stack(w_K)
                rms_rel = 0.0
            else:
                warm_K = w.fold_camera_matrices
                rms_rel = abs(w.holdout_rms_px / c.holdout_rms_px - 1.0)
            scale = np.maximum(np.abs(c.fold_camera_matrices), 1.0)
            worst = max(worst, float(np.max(np.abs(warm_K - c.fold_camera_matrices) / scale)), rms_rel)
        mc, mw, ms = (statistics.median(c) for c in (cpu_cold, cpu_warm, cpu_stop))
        iters = " | ".join(f"{statistics.median(it):.0f}, {max(it)}" for it in (it_cold, it_warm, it_stop))
        print(
            f"| {name} | {iters} | {mc * 1e3:.2f} | {mw * 1e3:.2f} | {ms * 1e3:.2f} | {ms / mc:.2f} "
            f"| {worst:.1e} |"
        )
    print(f"\nload {load_1min():.2f} at the end")


if __name__ == "__main__":
    main()
