"""Camera-IMU calibration on EuRoC MAV's imu_april recording: calibctl's joint estimator beside the plain
afternoon script, against EuRoC's published T_BS (camera into IMU body), for cam0 and cam1.

Data: chutsu/yac's ``yac/tests/test_data/calib/imu_april/`` (per-frame AprilGrid detections as
``camN/<ns>.csv``: ts, tag rows/cols/size/spacing, kp_x, kp_y, p_x, p_y, p_z, tag_id, corner_idx; the
200 Hz ``imu0.csv``: ts, w xyz rad/s, a xyz m/s^2; ``config.yaml``: the intrinsics (pinhole radtan4)
and the IMU noise densities). Its licence is EuRoC's and is not stated there: it is not in this
repository. Pass the folder as the first argument or in CALIBCTL_IMU_APRIL; without it the benchmark
says so and exits 0.

Compared in the IMU (EuRoC body) frame: T_imu_cam = T_BS, p_imu = R p_cam + t; the rotation difference
is the angle of R_calibctl R_euroc^T, the translation difference the norm of t_calibctl - t_euroc.
td: t_imu = t_cam + td (EuRoC's stamps are hardware-synchronised: td ~ 0). Then the IMU stamps are
shifted by --shift-ms and td must move by exactly that. Then the cost's growth with recording length
(the first 25/50/75/100 % of cam0). Also: the two cameras' PnP poses against EuRoC's own stereo
extrinsic (T_BS0^-1 T_BS1), which bounds how close any calibration with these held intrinsics can
come to EuRoC's published pair.

``--joint``: both cameras against ONE IMU trajectory, gravity and biases in one solve
(``calibrate_cameras``: each camera's own T_imu_cam and td), with the same +shift check; with
``--rig-pair`` also with cam1 held through yac's ``T_cam0_cam1`` (EuRoC's published stereo pair).
``--only-joint`` skips the one-camera runs, the growth sweep and the stereo check. ``--imu-model
scale-misalignment``: the joint runs with Kalibr's scale-misalignment IMU model (its 24 states printed
with their sigmas, and each camera's rotation from EuRoC's per IMU axis).

``--bias-walk``: the joint runs (and ``--growth``) with the biases as random walks.
``--kalibr-differences [NAME ...]``: the joint solve (no folds, no jackknife: the estimate does not depend
on them) under each of Kalibr's model choices that calibctl makes differently (``KALIBR_DIFFERENCES``),
one at a time and together.

Run: python benchmarks/bench_imu_euroc.py [FOLDER] [--shift-ms 5] [--knot-spacing-s 0.05]
     [--joint [--rig-pair] [--only-joint] [--imu-model scale-misalignment] [--bias-walk]]
     python benchmarks/bench_imu_euroc.py FOLDER --kalibr-differences [NAME ...]
     python benchmarks/bench_imu_euroc.py FOLDER --growth   (the cost's growth alone: 1/4, 1/2, all)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model, load_1min  # noqa: E402

from calibctl.core.extrinsics import se3  # noqa: E402
from calibctl.core.imu.calibrate import calibrate, calibrate_cameras  # noqa: E402
from calibctl.core.imu.intrinsics import IMU_MODELS  # noqa: E402
from calibctl.core.imu.intrinsics import NAMES as IMU_STATE_NAMES  # noqa: E402
from calibctl.core.imu.plain import board_track, plain_calibration  # noqa: E402
from calibctl.core.imu.rows import report_series, row_test  # noqa: E402
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples  # noqa: E402
from calibctl.core.imu.solve import SolveOptions, solve_imu_camera, solve_imu_cameras  # noqa: E402

# EuRoC MAV sensor.yaml T_BS (camera into body = IMU), as vendored by VINS-Mono (config/euroc) and
# ORB-SLAM3 (Examples/Stereo-Inertial/EuRoC.yaml).
EUROC_T_BS = {
    "cam0": np.array(
        [
            [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975],
            [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768],
            [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949],
            [0.0, 0.0, 0.0, 1.0],
        ]
    ),
    "cam1": np.array(
        [
            [0.0125552670891, -0.999755099723, 0.0182237714554, -0.0198435579556],
            [0.999598781151, 0.0130119051815, 0.0251588363115, 0.0453689425024],
            [-0.0253898008918, 0.0179005838253, 0.999517347078, 0.00786212447038],
            [0.0, 0.0, 0.0, 1.0],
        ]
    ),
}


# Kalibr's kalibr_calibrate_imu_camera defaults that calibctl's default solve makes differently, as
# SolveOptions fields (name -> fields; "rig_pair": cam1 held through yac's T_cam0_cam1, as Kalibr holds
# the camera chain's baselines); the spline's order (Kalibr: 6, quintic) is not an option here.
KALIBR_WEIGHTING = {"fix_corner_sigma": True, "corner_sigma_px": 1.0, "fix_imu_sigma": True}
KALIBR_DIFFERENCES: dict[str, dict[str, object]] = {
    "calibctl": {},
    "bias-walk": {"bias_walk": True},
    "kalibr-weighting": KALIBR_WEIGHTING,
    "knots-0.025": {"knot_spacing_s": 0.025},
    "knots-0.01": {"knot_spacing_s": 0.01},
    "knots-0.01+bias-walk": {"knot_spacing_s": 0.01, "bias_walk": True},
    "knots-0.01+kalibr-weighting": {"knot_spacing_s": 0.01, **KALIBR_WEIGHTING},
    "rig-pair": {"rig_pair": True},
    "kalibr": {"knot_spacing_s": 0.01, "bias_walk": True, **KALIBR_WEIGHTING},
    "kalibr+rig-pair": {"knot_spacing_s": 0.01, "bias_walk": True, **KALIBR_WEIGHTING, "rig_pair": True},
}


def load(folder: Path, cam: str, shift_s: float = 0.0, keep: tuple[float, float] = (0.0, 1.0)):
    """(ImuSamples, CameraFrames, ImuNoise) from the yac layout; times in s from the first IMU stamp
    (plus ``shift_s`` on the IMU); only the frames from share keep[0] to keep[1] of the recording."""
    config = yaml.safe_load((folder / "config.yaml").read_text())
    raw = np.loadtxt(folder / "imu0.csv", delimiter=",", comments="#")
    t0 = int(raw[0, 0])
    stamps = np.loadtxt(folder / "imu0.csv", delimiter=",", comments="#", usecols=0, dtype=np.int64)
    imu = ImuSamples((stamps - t0) * 1e-9 + shift_s, raw[:, 1:4], raw[:, 4:7])
    files = sorted((folder / cam).glob("*.csv"))
    files = files[int(round(keep[0] * len(files))) : int(round(keep[1] * len(files)))]
    t, objs, imgs = [], [], []
    for f in files:
        t.append((int(f.stem) - t0) * 1e-9)
        rows = (
            np.loadtxt(f, delimiter=",", comments="#", ndmin=2)
            if f.stat().st_size > 200
            else np.zeros((0, 12))
        )
        objs.append(rows[:, 7:10])
        imgs.append(rows[:, 5:7])
    fx, fy, cx, cy = config[cam]["proj_params"]
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    frames = CameraFrames(
        np.array(t),
        tuple(objs),
        tuple(imgs),
        K,
        np.array(config[cam]["dist_params"]),
        tuple(config[cam]["resolution"]),
    )
    i = config["imu0"]
    noise = ImuNoise(i["sigma_g_c"], i["sigma_a_c"], i["sigma_gw_c"], i["sigma_aw_c"], i["g"])
    return imu, frames, noise


def difference(T: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(deg, mm) between two T_imu_cam."""
    return (
        float(np.degrees(se3.rotation_angle_rad(T[:3, :3] @ ref[:3, :3].T))),
        float(1e3 * np.linalg.norm(T[:3, 3] - ref[:3, 3])),
    )


def stereo_check(folder: Path) -> tuple[float, float]:
    """Median relative pose of the two cameras' PnP poses at shared stamps against EuRoC's pair."""
    _, f0, _ = load(folder, "cam0")
    _, f1, _ = load(folder, "cam1")
    a, b = board_track(f0), board_track(f1)
    common, ia, ib = np.intersect1d(np.round(a.t_s, 4), np.round(b.t_s, 4), return_indices=True)
    ref = np.linalg.inv(EUROC_T_BS["cam0"]) @ EUROC_T_BS["cam1"]
    rel = a.T_cam_w[ia] @ np.linalg.inv(b.T_cam_w[ib])
    rot = np.median(se3.rotvecs_from_rotations(rel[:, :3, :3] @ ref[:3, :3].T), axis=0)
    tr = np.median(rel[:, :3, 3] - ref[:3, 3], axis=0)
    return float(np.degrees(np.linalg.norm(rot))), float(1e3 * np.linalg.norm(tr))


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("folder", nargs="?", default=os.environ.get("CALIBCTL_IMU_APRIL"))
    parser.add_argument("--shift-ms", type=float, default=5.0)
    parser.add_argument("--knot-spacing-s", type=float, default=SolveOptions().knot_spacing_s)
    parser.add_argument("--no-growth", action="store_true", help="skip the recording-length sweep")
    parser.add_argument("--quarters", action="store_true", help="solve each quarter of cam0 alone")
    parser.add_argument("--joint", action="store_true", help="both cameras against one IMU in one solve")
    parser.add_argument("--rig-pair", action="store_true", help="--joint with cam1 held by T_cam0_cam1")
    parser.add_argument("--only-joint", action="store_true", help="only the joint runs")
    parser.add_argument(
        "--imu-model", choices=IMU_MODELS, default="calibrated", help="the joint runs' IMU model"
    )
    parser.add_argument(
        "--growth",
        action="store_true",
        help="only the cost's growth: cam0's first 1/4, 1/2 and all of it, solved as `imu solve` does "
        "(3-fold held-out, jackknife, gates), then the row test and the report's series",
    )
    parser.add_argument(
        "--bias-walk", action="store_true", help="the joint runs' (and --growth's) biases as random walks"
    )
    parser.add_argument(
        "--kalibr-differences",
        nargs="*",
        choices=list(KALIBR_DIFFERENCES),
        help="only the joint solve under Kalibr's model choices (all when none named)",
    )
    args = parser.parse_args()
    if not args.folder or not (Path(args.folder) / "imu0.csv").is_file():
        print("no imu_april folder (pass it or set CALIBCTL_IMU_APRIL): skipped")
        return 0
    warnings.simplefilter("ignore")
    folder = Path(args.folder)
    print(
        f"# {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} CPUs ({cpu_model()}), "
        f"load {load_1min():.1f}, knot spacing {args.knot_spacing_s} s"
    )
    if args.growth:
        growth(
            folder,
            SolveOptions(knot_spacing_s=args.knot_spacing_s, bias_walk=args.bias_walk),
            (0.25, 0.5, 1.0),
        )
        return 0
    if args.kalibr_differences is not None:
        kalibr_differences(folder, args.kalibr_differences or list(KALIBR_DIFFERENCES))
        return 0
    options = SolveOptions(knot_spacing_s=args.knot_spacing_s)
    if args.joint or args.only_joint:
        joint_options = replace(options, imu_model=args.imu_model, bias_walk=args.bias_walk)
        joint(folder, joint_options, args.shift_ms, args.rig_pair)
    if args.only_joint:
        return 0
    for cam in ("cam0", "cam1"):
        imu, frames, noise = load(folder, cam)
        ref = EUROC_T_BS[cam]
        c0 = time.process_time()
        track = board_track(frames)
        plain = plain_calibration(imu, frames, track)
        plain_cpu = time.process_time() - c0
        c0 = time.process_time()
        cal = calibrate(imu, frames, noise, options)
        cpu = time.process_time() - c0
        s = cal.solution
        assert s is not None
        deg, mm = difference(plain.T_imu_cam, ref)
        print(
            f"{cam} plain    : {deg:.3f} deg {mm:5.1f} mm  td {1e3 * plain.td_s:+.3f} ms  "
            f"cpu {plain_cpu:.1f} s"
        )
        deg, mm = difference(s.T_imu_cam, ref)
        print(
            f"{cam} calibctl : {deg:.3f} deg {mm:5.1f} mm  td {1e3 * s.td_s:+.3f} ms  cpu {cpu:.1f} s "
            f"(solve {s.cpu_s:.1f} s incl. {len(s.held_out.corner_rms_px) if s.held_out else 0}-fold)  "
            f"{s.n_frames} frames {s.n_imu} IMU samples, {s.iterations} iterations"
        )
        print(
            f"    sigma rot {np.round(s.sigma_rotation_deg, 4)} deg, "
            f"t {np.round(s.sigma_translation_mm, 2)} mm, "
            f"td {s.sigma_td_ms:.4f} ms (CRLB {s.td_crlb_ms:.4f} ms); RMS {s.corner_rms_px:.3f} px, "
            f"gyro {s.gyro_rms_rad_s:.4f} rad/s, accel {s.accel_rms_m_s2:.3f} m/s^2 (IMU sigma x "
            f"{s.imu_variance_factors[0]:.1f}, x {s.imu_variance_factors[1]:.1f}); corner sigma "
            f"{s.corner_sigma_px:.3f} px"
        )
        if s.held_out:
            print(
                f"    held-out RMS {np.round(s.held_out.corner_rms_px, 3)} px, gyro "
                f"{np.round(s.held_out.gyro_rms_rad_s, 4)}, accel {np.round(s.held_out.accel_rms_m_s2, 3)}"
            )
        print(
            "    gates: "
            + "; ".join(f"{g.gate} {'ok' if g.passed else 'FAIL'} {g.value:.3g}" for g in cal.gates)
        )
        shifted_imu = ImuSamples(imu.t_s + args.shift_ms * 1e-3, imu.gyro_rad_s, imu.accel_m_s2)
        moved = solve_imu_camera(
            shifted_imu, frames, noise, SolveOptions(knot_spacing_s=args.knot_spacing_s, folds=0)
        )
        plain_moved = plain_calibration(shifted_imu, frames, track)
        print(
            f"    IMU stamps +{args.shift_ms:g} ms: calibctl td moved {1e3 * (moved.td_s - s.td_s):+.3f} ms, "
            f"plain {1e3 * (plain_moved.td_s - plain.td_s):+.3f} ms"
        )
    deg, mm = stereo_check(folder)
    print(f"cam0-cam1 PnP poses against EuRoC's stereo pair: {deg:.3f} deg {mm:.1f} mm (median)")
    if not args.no_growth:
        growth(folder, SolveOptions(knot_spacing_s=args.knot_spacing_s, folds=0), (0.25, 0.5, 0.75, 1.0))
    if args.quarters:
        quarters(folder, args.knot_spacing_s)
    return 0


def joint(folder: Path, options: SolveOptions, shift_ms: float, rig_pair: bool) -> None:
    """Both cameras and one IMU in one solve (calibrate_cameras), the shift check on the same solve, and
    optionally cam1 held through yac's T_cam0_cam1."""
    imu, f0, noise = load(folder, "cam0")
    _, f1, _ = load(folder, "cam1")
    c0 = time.process_time()
    cals = calibrate_cameras(imu, [f0, f1], noise, options)
    cpu = time.process_time() - c0
    for cam, cal in zip(("cam0", "cam1"), cals, strict=True):
        s = cal.solution
        assert s is not None
        deg, mm = difference(s.T_imu_cam, EUROC_T_BS[cam])
        print(
            f"{cam} joint    : {deg:.3f} deg {mm:5.2f} mm  td {1e3 * s.td_s:+.3f} ms  "
            f"cpu {cpu:.1f} s for both ({s.iterations} iterations); "
            f"sigma rot {np.round(s.sigma_rotation_deg, 4)} deg, t {np.round(s.sigma_translation_mm, 2)} mm, "
            f"td {s.sigma_td_ms:.4f} ms; RMS {s.corner_rms_px:.3f} px; "
            f"gates {'pass' if cal.passed else 'FAIL ' + ', '.join(g.gate for g in cal.failed)}"
        )
        d_rot = se3.rotvecs_from_rotations((s.T_imu_cam[:3, :3] @ EUROC_T_BS[cam][:3, :3].T)[None])[0]
        print(f"    rotation from EuRoC's about IMU x, y, z: {np.round(np.degrees(d_rot), 3)} deg")
        if s.imu_intrinsics is not None:  # the gyro triad's view of the camera: C_gyro_i R_imu_cam
            R_gc = s.imu_intrinsics.C_gyro_i @ s.T_imu_cam[:3, :3]
            d_gyro = se3.rotvecs_from_rotations((R_gc @ EUROC_T_BS[cam][:3, :3].T)[None])[0]
            print(f"    gyro triad's rotation from EuRoC's: {np.round(np.degrees(d_gyro), 3)} deg")
    m = cals[0].solution.imu_intrinsics if cals[0].solution is not None else None
    if m is not None:
        print(f"    IMU model {m.model}: least-seen information {m.min_information:.1f} (prior-scaled)")
        for name, x, sd in zip(IMU_STATE_NAMES, m.x, m.sigma, strict=True):
            print(f"      {name:6s} {x:+.5f} +/- {sd:.5f}")
    shifted = ImuSamples(imu.t_s + shift_ms * 1e-3, imu.gyro_rad_s, imu.accel_m_s2)
    plain_opts = replace(options, folds=0, jackknife_blocks=0)
    base = solve_imu_cameras(imu, [f0, f1], noise, plain_opts)
    moved = solve_imu_cameras(shifted, [f0, f1], noise, plain_opts)
    print(
        f"    IMU stamps +{shift_ms:g} ms: joint td moved "
        + ", ".join(f"{1e3 * (m.td_s - b.td_s):+.3f}" for m, b in zip(moved, base, strict=True))
        + " ms"
    )
    if rig_pair:
        config = yaml.safe_load((folder / "config.yaml").read_text())
        T01 = np.array(config["T_cam0_cam1"]["data"], np.float64).reshape(4, 4)
        c0 = time.process_time()
        tied = solve_imu_cameras(imu, [f0, f1], noise, plain_opts, rig=[None, T01])
        cpu = time.process_time() - c0
        for cam, s in zip(("cam0", "cam1"), tied, strict=True):
            deg, mm = difference(s.T_imu_cam, EUROC_T_BS[cam])
            print(
                f"{cam} rig pair: {deg:.3f} deg {mm:5.2f} mm  td {1e3 * s.td_s:+.3f} ms  "
                f"cpu {cpu:.1f} s for both"
            )


def kalibr_differences(folder: Path, names: list[str]) -> None:
    """The joint solve of both cameras under each named set of Kalibr's choices: each camera's distance
    from EuRoC's T_BS, its rotation from it about the IMU axes, td, the IMU residuals, the CPU."""
    imu, f0, noise = load(folder, "cam0")
    _, f1, _ = load(folder, "cam1")
    config = yaml.safe_load((folder / "config.yaml").read_text())
    T01 = np.array(config["T_cam0_cam1"]["data"], np.float64).reshape(4, 4)
    for name in names:
        fields = dict(KALIBR_DIFFERENCES[name])
        rig = [None, T01] if fields.pop("rig_pair", False) else None
        options = replace(SolveOptions(folds=0, jackknife_blocks=0), **fields)  # type: ignore[arg-type]
        c0 = time.process_time()
        sols = solve_imu_cameras(imu, [f0, f1], noise, options, rig=rig)
        cpu = time.process_time() - c0
        for cam, s in zip(("cam0", "cam1"), sols, strict=True):
            deg, mm = difference(s.T_imu_cam, EUROC_T_BS[cam])
            d_rot = se3.rotvecs_from_rotations((s.T_imu_cam[:3, :3] @ EUROC_T_BS[cam][:3, :3].T)[None])[0]
            d_t = 1e3 * (s.T_imu_cam[:3, 3] - EUROC_T_BS[cam][:3, 3])
            print(
                f"{name:28s} {cam}: {deg:.3f} deg {mm:5.2f} mm td {1e3 * s.td_s:+.3f} ms; about IMU x y z "
                f"{np.round(np.degrees(d_rot), 3)} deg, t {np.round(d_t, 2)} mm; gyro "
                f"{s.gyro_rms_rad_s:.4f} rad/s accel {s.accel_rms_m_s2:.3f} m/s^2 (x "
                f"{s.imu_variance_factors[0]:.2f}, {s.imu_variance_factors[1]:.2f}); corner sigma "
                f"{s.corner_sigma_px:.3f} px; {s.iterations} iterations (converged {s.converged}), "
                f"cpu {cpu:.1f} s for both (load {load_1min():.1f})"
            )


def growth(folder: Path, options: SolveOptions, shares: tuple[float, ...]) -> None:
    """CPU and wall time of ``calibrate`` on cam0's first ``shares`` of the recording, and of what the
    workflow adds after it (the row test and the report's series, core.imu.rows), with the row test's
    verdict: EuRoC's cameras are global-shutter, so a significant ramp would be a false alarm."""
    for share in shares:
        imu, frames, noise = load(folder, "cam0", keep=(0.0, share))
        c0, w0 = time.process_time(), time.perf_counter()
        cal = calibrate(imu, frames, noise, options)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        s = cal.solution
        assert s is not None
        c0 = time.process_time()
        track = board_track(frames)
        rows = row_test(s, frames, track)
        report_series(s, imu, frames, track)
        extra = time.process_time() - c0
        print(
            f"length {100 * share:3.0f} %: {s.n_frames} frames {s.n_imu} IMU samples {s.knots.n} knots: "
            f"calibrate cpu {cpu:.1f} s (wall {wall:.1f} s, load {load_1min():.1f}), {s.iterations} "
            f"iterations, {1e3 * cpu / s.n_frames:.1f} ms cpu per frame; row test + series cpu {extra:.2f} s"
        )
        print(f"    row test: {rows.message if rows else 'not run'}")


def quarters(folder: Path, knot_spacing_s: float) -> None:
    """Each quarter of cam0 solved alone: the spread of the four answers against the sigma each reports
    (the white-noise sigma cannot see correlated residuals such as vibration; the spread can)."""
    answers = []
    for q in range(4):
        imu, frames, noise = load(folder, "cam0", keep=(q / 4, (q + 1) / 4))
        s = solve_imu_camera(imu, frames, noise, SolveOptions(knot_spacing_s=knot_spacing_s, folds=0))
        deg, mm = difference(s.T_imu_cam, EUROC_T_BS["cam0"])
        answers.append(np.r_[se3.rotvec_from_rotation(s.T_imu_cam[:3, :3]), s.T_imu_cam[:3, 3], s.td_s])
        print(
            f"quarter {q + 1}: {deg:.3f} deg {mm:.1f} mm td {1e3 * s.td_s:+.3f} ms; sigma rot "
            f"{np.round(s.sigma_rotation_deg, 4)} deg, t {np.round(s.sigma_translation_mm, 2)} mm, "
            f"td {s.sigma_td_ms:.4f} ms"
        )
    sd = np.std(np.array(answers), axis=0, ddof=1)
    print(
        f"spread of the quarters (sd): rot {np.round(np.degrees(sd[:3]), 4)} deg, t "
        f"{np.round(1e3 * sd[3:6], 2)} mm, td {1e3 * sd[6]:.4f} ms"
    )


if __name__ == "__main__":
    raise SystemExit(main())
