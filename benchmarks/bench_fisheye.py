"""Fisheye (equidistant Kannala-Brandt): is calibctl's sigma honest, and how does plain cv2.fisheye do on the
same corners?

Sessions (calibctl.core.synth.fisheye, corner level): 1280x960, fields of view cycling 150 / 170 / 190 deg,
circular and full-frame alternating (full-frame at 150 and 170 only: a 190 deg full-frame lens puts most
of the frame behind the camera plane), k = (0.02, -0.006, 0.001, -0.0002), principal point off-centre
(+3.3, -2.1 px), 15-20 views (15 + i % 6) of a 9 x 6 board tilted 15-45 deg, every fourth view in the
outer band of the field, 0.2 px Gaussian corner noise, seed = SEED_BASE + i. z = (estimate - truth) /
reported sigma for every parameter; honest sigma gives mean 0, std 1 (the issue's bar: |mean| <= 0.3,
0.7 <= std <= 1.5 over >= 30 sessions, fx and cx). Each session is solved again with its noise negated
(``flipped_noise``): the mean of (z + z_twin) / 2 is the solve's own bias, free of the noise's sampling.

Plain OpenCV: cv2.fisheye.calibrate on the same corners with CALIB_RECOMPUTE_EXTRINSIC | CALIB_FIX_SKEW and
its own initialisation (what a user calling it directly gets), and again from calibctl's focal guess
(CALIB_USE_INTRINSIC_GUESS). Reported: did it return, its fx error, its RMS.

mrcal (Debian python3-mrcal, run by /usr/bin/python3 in a subprocess; never a calibctl dependency) on the same
corners of the first N_MRCAL sessions: mrcal has no equidistant Kannala-Brandt model, and its OpenCV models
are pinhole (nothing at or beyond 90 deg off-axis), so the fisheye-capable choice is
LENSMODEL_SPLINED_STEREOGRAPHIC (order 3, 16 x 12 knots, fov_x = the lens's field of view): a stereographic
core plus a spline, run as mrcal-calibrate-cameras on a corners.vnl with --imagersize (no images), the
focal seed = calibctl's focal guess, board warp not solved (the renders are flat). Reported: did it run,
its per-corner RMS over inliers (OpenCV's definition, benchmarks/mrcal_solve.py), outliers it dropped, CPU
s. Its fx is the stereographic core's, which the spline can trade with: not comparable with the truth's.

Run: python benchmarks/bench_fisheye.py [N_SESSIONS] [SEED_BASE] [N_MRCAL]   (default 30, 0, 6)
"""

from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime

import cv2
import numpy as np

from calibctl.core.intrinsics.fisheye_model import focal_guess_px
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model  # noqa: E402

SIZE = (1280, 960)
PARAMS = ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")
LENSES = ((150.0, True), (170.0, False), (190.0, True), (150.0, False), (170.0, True), (190.0, True))


def session(i: int, seed_base: int = 0):
    fov, circular = LENSES[i % len(LENSES)]
    cam = FisheyeCamera.from_fov(SIZE, fov, circular)
    return cam, synthesize_fisheye_session(cam, 15 + i % 6, seed=seed_base + i, noise_px=0.2)


def flipped_noise(s) -> list[np.ndarray]:
    """The session's corners with its noise negated (true + (true - noisy)): the antithetic twin. A solve that
    is unbiased gives z(twin) = -z(session) up to its nonlinearity, so (z + z_twin) / 2 is its bias."""
    return [2 * t - p for t, p in zip(s.true_image_points_per_view, s.image_points_per_view, strict=True)]


MRCAL_PY = "/usr/bin/python3"
MRCAL_TOOL = "/usr/bin/mrcal-calibrate-cameras"
MRCAL_SPLINE = "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg={fov:.0f}"


def mrcal_available() -> str | None:
    """None when the system python imports mrcal, else why not."""
    try:
        done = subprocess.run([MRCAL_PY, "-c", "import mrcal"], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return str(exc)
    return None if done.returncode == 0 else (done.stderr.strip().splitlines() or ["import failed"])[-1]


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_mrcal(cam: FisheyeCamera, s, focal_px: float, work: str) -> dict:
    """mrcal-calibrate-cameras with the splined stereographic model on the session's corners (see the
    docstring)."""
    vnl = os.path.join(work, "corners.vnl")
    rows = ["# filename x y level"]
    for k, px in enumerate(s.image_points_per_view):
        rows += [f"view-{k:03d}.png {x:.6f} {y:.6f} 0" for x, y in px]
    with open(vnl, "w", encoding="utf-8") as fh:
        fh.write("\n".join(rows) + "\n")
    args = [
        MRCAL_TOOL,
        "--corners-cache",
        vnl,
        "--imagersize",
        str(SIZE[0]),
        str(SIZE[1]),
        "--lensmodel",
        MRCAL_SPLINE.format(fov=cam.fov_deg),
        "--focal",
        f"{focal_px:.0f}",
        "--object-spacing",
        "0.025",
        "--object-width-n",
        "9",
        "--object-height-n",
        "6",
        "--skip-calobject-warp-solve",
        "--outdir",
        work,
        "view-*.png",
    ]
    cpu = children_cpu_s()
    done = subprocess.run(args, cwd=work, capture_output=True, text=True)
    cpu = children_cpu_s() - cpu
    if done.returncode != 0:
        return {
            "outcome": f"exit {done.returncode}: {(done.stderr.strip().splitlines() or ['?'])[-1][-70:]}",
            "cpu_s": cpu,
        }
    helper = os.path.join(os.path.dirname(os.path.abspath(__file__)), "mrcal_solve.py")
    out = subprocess.run(
        [MRCAL_PY, helper, "evaluate", os.path.join(work, "camera-0.cameramodel")],
        capture_output=True,
        text=True,
        check=True,
    )
    return {"outcome": "solved", "cpu_s": cpu, **json.loads(out.stdout.strip().splitlines()[-1])}


def mrcal_table(n_mrcal: int, seed_base: int) -> None:
    why = mrcal_available()
    if why is not None:
        print(f"mrcal: not run ({MRCAL_PY} cannot import mrcal: {why})")
        return
    print(f"mrcal {MRCAL_SPLINE.format(fov=0).replace('=0', '=FOV')} vs calibctl on the same corners:\n")
    print(
        "| seed | fov deg | lens | calibctl RMS px | calibctl CPU s | mrcal | mrcal RMS px (inliers) | "
        "outliers "
        "| mrcal CPU s | mrcal core fx / true fx |\n|---|---|---|---|---|---|---|---|---|---|"
    )
    for i in range(n_mrcal):
        cam, s = session(i, seed_base)
        cpu = time.process_time()
        sol = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "fisheye")
        cpu = time.process_time() - cpu
        focal = focal_guess_px(s.object_points_per_view, s.image_points_per_view, SIZE)
        with tempfile.TemporaryDirectory(prefix="bench-fisheye-mrcal-") as work:
            m = run_mrcal(cam, s, focal, work)
        solved = m["outcome"] == "solved"
        print(
            f"| {seed_base + i} | {cam.fov_deg:.0f} | {'circular' if cam.circle_radius_px else 'full-frame'} "
            f"| {sol.rms_px:.3f} | {cpu:.2f} | {m['outcome']} | "
            f"{m['rms_px'] if solved else float('nan'):.3f} "
            f"| {m.get('n_outliers', '-')} | {m['cpu_s']:.2f} | "
            f"{(str(round(m['fx'], 1)) + ' / ' + str(round(cam.K[0, 0], 1))) if solved else '-'} |"
        )


def z_scores(cam: FisheyeCamera, sol) -> dict[str, float]:
    truth = (cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2], *cam.dist)
    est = (sol.fx, sol.fy, sol.cx, sol.cy, *sol.dist_coeffs)
    return {p: (e - t) / sol.sigma[p] for p, e, t in zip(PARAMS, est, truth, strict=True)}


def plain_opencv(s, guess_px: float | None = None) -> tuple[str, float | None, float | None, float]:
    """(outcome, fx, rms, seconds) of cv2.fisheye.calibrate run the way its documentation shows; with
    ``guess_px`` it starts from that focal length and the image centre (CALIB_USE_INTRINSIC_GUESS)."""
    obj = [o.reshape(1, -1, 3).astype(np.float64) for o in s.object_points_per_view]
    img = [p.reshape(1, -1, 2).astype(np.float64) for p in s.image_points_per_view]
    flags = cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW
    K0 = np.zeros((3, 3))
    if guess_px is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
        K0 = np.array([[guess_px, 0, (SIZE[0] - 1) / 2], [0, guess_px, (SIZE[1] - 1) / 2], [0, 0, 1.0]])
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    t = time.perf_counter()
    try:
        rms, K, _D, _r, _t = cv2.fisheye.calibrate(
            obj, img, SIZE, K0, np.zeros((4, 1)), flags=flags, criteria=criteria
        )
    except cv2.error as exc:
        return f"error: {str(exc).strip().splitlines()[-1][-60:]}", None, None, time.perf_counter() - t
    return "returned", float(K[0, 0]), float(rms), time.perf_counter() - t


def main(n: int = 30, seed_base: int = 0, n_mrcal: int = 6) -> None:
    rows, zs, twins, plain, guided, times = [], [], [], [], [], []
    for i in range(n):
        cam, s = session(i, seed_base)
        t = time.perf_counter()
        sol = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "fisheye")
        times.append(time.perf_counter() - t)
        z = z_scores(cam, sol)
        zs.append([z[p] for p in PARAMS])
        twin = z_scores(cam, solve_intrinsics(s.object_points_per_view, flipped_noise(s), SIZE, "fisheye"))
        twins.append([twin[p] for p in PARAMS])
        outcome, fx_cv, rms_cv, t_cv = plain_opencv(s)
        plain.append((outcome, fx_cv, rms_cv, t_cv))
        guided.append(
            plain_opencv(s, focal_guess_px(s.object_points_per_view, s.image_points_per_view, SIZE))
        )
        rows.append(
            (
                i,
                cam.fov_deg,
                "circular" if cam.circle_radius_px else "full-frame",
                len(s.image_points_per_view),
                cam.K[0, 0],
                sol.fx,
                sol.sigma["fx"],
                sol.rms_px,
                outcome,
                fx_cv,
                rms_cv,
            )
        )
    Z, bias = np.array(zs), (np.array(zs) + np.array(twins)) / 2
    print(
        f"machine: {cpu_model()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"OpenCV {cv2.__version__}; {datetime.now(UTC):%Y-%m-%d %H:%M} UTC; load {os.getloadavg()[0]:.1f}\n"
    )
    print(
        "| parameter | mean z | std z | max abs z | bar (abs mean <= 0.3, 0.7 <= std <= 1.5) | bias "
        "(antithetic) |\n"
        "|---|---|---|---|---|---|"
    )
    for k, p in enumerate(PARAMS):
        m, sd = Z[:, k].mean(), Z[:, k].std(ddof=1)
        print(
            f"| {p} | {m:+.3f} | {sd:.3f} | {np.abs(Z[:, k]).max():.2f} | "
            f"{'pass' if abs(m) <= 0.3 and 0.7 <= sd <= 1.5 else 'FAIL'} | {bias[:, k].mean():+.4f} |"
        )
    ok = [p for p in plain if p[0] == "returned"]
    err_cv = [abs(r[9] - r[4]) for r in rows if r[9] is not None]
    err_us = [abs(r[5] - r[4]) for r in rows]
    print(
        f"\ncalibctl: {n}/{n} solved, median |fx error| {np.median(err_us):.3f} px, "
        f"{1000 * np.median(times):.0f} ms median per solve"
    )
    print(
        f"plain cv2.fisheye.calibrate: {len(ok)}/{n} returned, median |fx error| "
        f"{np.median(err_cv) if err_cv else float('nan'):.3f} px, max "
        f"{max(err_cv) if err_cv else float('nan'):.2f} px, "
        f"{1000 * np.median([p[3] for p in plain]):.0f} ms median per call"
    )
    good = [g for g in guided if g[0] == "returned" and g[2] is not None and g[2] < 1.0]
    print(
        f"cv2.fisheye.calibrate from calibctl's focal guess: {len(good)}/{n} reached RMS < 1 px, median RMS "
        f"{np.median([g[2] for g in guided if g[2] is not None]):.3f} px, "
        f"{1000 * np.median([g[3] for g in guided]):.0f} ms median per call\n"
    )
    print(
        "| seed | fov deg | lens | views | true fx | calibctl fx | sigma fx | calibctl RMS | cv2.fisheye | "
        "cv2 fx | cv2 RMS |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        cv_fx = f"{r[9]:.2f}" if r[9] is not None else "-"
        cv_rms = f"{r[10]:.3f}" if r[10] is not None else "-"
        print(
            f"| {r[0] + seed_base} | {r[1]:.0f} | {r[2]} | {r[3]} | {r[4]:.2f} | {r[5]:.2f} | {r[6]:.3f} | "
            f"{r[7]:.3f} "
            f"| {r[8]} | {cv_fx} | {cv_rms} |"
        )

    print()
    mrcal_table(min(n, n_mrcal), seed_base)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:4]))
