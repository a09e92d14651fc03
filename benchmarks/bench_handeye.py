"""Hand-eye A X = X B: calibctl against OpenCV 4's cv2.calibrateHandEye on the same seeded data.

Sections (all seeded; X = T_a_b known):
1. accuracy on pose logs (3-D excitation, 30 keyframes, 0.05 deg + 2 mm noise per pose), N seeds;
2. robot arm on rendered photos (camera on a gripper, 15 poses): calibctl end to end (detection,
   solvePnP on the camera's intrinsics, solve) and OpenCV 4 on calibctl's board poses;
3. degenerate and unsynchronised logs (corridor, planar, 80 ms time offset): what each tool returns;
4. is the reported lever-arm sigma honest: z = (t - t_true) / sigma over N runs of 12 motions;
5. the seed's conditioning table: propagated sigma against a Monte Carlo of the planar solve;
6. speed of one solve (15 and 200 poses), best of R in-process calls.

OpenCV 5 (the project's) has no calibrateHandEye: OpenCV 4 runs in another interpreter given by
--opencv4-python (a throwaway venv with opencv-python-headless<5), via benchmarks/opencv4_handeye.py.
Without it those columns are left out.

Run: python benchmarks/bench_handeye.py [--seeds 50] [--repeats 20] [--opencv4-python /tmp/cv4venv/bin/python]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import detect_board
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.extrinsics.handeye import Motions, lever_arm_sigma_m
from calibctl.core.extrinsics.handeye_gates import (
    HandEyeThresholds,
    consistency_gate,
    evaluate_handeye_gates,
    translation_scale_gate,
)
from calibctl.core.extrinsics.handeye_refine import fit_handeye
from calibctl.core.extrinsics.motion_synth import robot_arm_poses, synthesize_motions, synthesize_pose_log
from calibctl.core.synth.pinhole import PinholeCamera, render_view
from calibctl.core.synth.scenes import scenario_poses

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import cpu_model  # noqa: E402

HERE = Path(__file__).resolve().parent
X_TRUE = se3.transform(
    se3.rotation_from_rotvec(np.radians([10.0, -20.0, 90.0])), np.array([0.12, -0.05, 0.30])
)
X_GRIPPER_CAM = se3.transform(
    se3.rotation_from_rotvec(np.radians([4.0, -3.0, 90.0])), np.array([0.05, -0.03, 0.10])
)
CV4_METHODS = ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")


def errors(T: np.ndarray, X: np.ndarray) -> tuple[float, float]:
    """(rotation error deg, translation error mm)."""
    return (
        float(np.degrees(se3.rotation_angle_rad(T[:3, :3].T @ X[:3, :3]))),
        float(np.linalg.norm(T[:3, 3] - X[:3, 3]) * 1e3),
    )


def cv4_case(T_wa_a: np.ndarray, T_wb_b: np.ndarray) -> dict[str, np.ndarray]:
    """OpenCV's eye-in-hand inputs: T_base_gripper = a's pose, T_target_cam... inverted: T_cam_target."""
    T_b_wb = np.array([se3.invert(T) for T in T_wb_b])
    return {
        "R_gripper2base": T_wa_a[:, :3, :3],
        "t_gripper2base": T_wa_a[:, :3, 3:],
        "R_target2cam": T_b_wb[:, :3, :3],
        "t_target2cam": T_b_wb[:, :3, 3:],
    }


def run_cv4(python: str | None, cases: dict[str, dict[str, np.ndarray]], repeats: int) -> dict | None:
    if not python:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cases.npz"
        np.savez(path, **{f"{name}/{k}": v for name, case in cases.items() for k, v in case.items()})
        done = subprocess.run(
            [python, str(HERE / "opencv4_handeye.py"), str(path), str(repeats)],
            capture_output=True,
            text=True,
            check=True,
        )
    return json.loads(done.stdout)


def calibctl_solve(T_wa_a: np.ndarray, T_wb_b: np.ndarray, method: str = "park"):
    motions = Motions.from_poses(T_wa_a, T_wb_b, tuple(str(i) for i in range(len(T_wa_a))))
    failed = [g.message for g in evaluate_handeye_gates(motions) if not g.passed]
    fit = None if failed else fit_handeye(motions, method)
    # the gates `calibctl handeye` applies after the solve, in its order (workflows.handeye.handeye)
    for gate in (
        ()
        if fit is None
        else (consistency_gate(fit, HandEyeThresholds()), translation_scale_gate(motions, fit))
    ):
        if not gate.passed:
            return None, [gate.message]
    return fit, failed


def stats(values: list[float]) -> str:
    v = np.array(values)
    return f"{np.median(v):.3f} / {np.percentile(v, 95):.3f}"


def section_accuracy(seeds: int, cv4: str | None) -> tuple[list[str], dict]:
    logs = {
        f"acc{s}": synthesize_pose_log(X_TRUE, 30, noise_rotation_deg=0.05, noise_translation_m=0.002, seed=s)
        for s in range(seeds)
    }
    rows: dict[str, tuple[list[float], list[float]]] = {}
    for method in ("park", "tsai"):
        rot, trans = [], []
        for log in logs.values():
            fit, failed = calibctl_solve(log.T_first, log.T_second, method)
            assert fit is not None, failed
            r, t = errors(fit.T_a_b, X_TRUE)
            rot.append(r)
            trans.append(t)
        rows[f"calibctl {method} + joint refinement"] = (rot, trans)
    res = run_cv4(cv4, {k: cv4_case(v.T_first, v.T_second) for k, v in logs.items()}, 1)
    if res:
        for m in CV4_METHODS:
            pairs = [errors(np.array(res["cases"][k][m]["T_gripper_cam"]), X_TRUE) for k in logs]
            rows[f"OpenCV {res['opencv_version']} {m}"] = ([p[0] for p in pairs], [p[1] for p in pairs])
    out = [
        f"## 1. Accuracy on pose logs ({seeds} seeds, 30 keyframes, 3-D excitation +/-45 deg, "
        "noise 0.05 deg + 2 mm per pose)",
        "",
        "| solver | rotation error deg, median / 95th pct | translation error mm, median / 95th pct |",
        "|---|---|---|",
    ]
    out += [f"| {name} | {stats(r)} | {stats(t)} |" for name, (r, t) in rows.items()]
    return out + [""], res or {}


def section_robot(scenes: int, cv4: str | None) -> list[str]:
    camera = PinholeCamera.seed_reference()
    spec = BoardSpec.chessboard(9, 6, 0.025)
    model = spec.object_points()
    ours, cases = [], {}
    for s in range(scenes):
        rng = np.random.default_rng(100 + s)
        T_cam_board = scenario_poses("good", camera, spec, 15, rng)
        T_base_gripper = robot_arm_poses(T_cam_board, X_GRIPPER_CAM)
        solved = []
        for T in T_cam_board:
            detection, _ = detect_board(render_view(camera, spec, T, rng), spec)
            assert detection is not None
            solved.append(
                estimate_board_pose(model[detection.corner_ids], detection.corners_px, camera.K, camera.dist)[
                    0
                ]
            )
        T_board_cam = np.array([se3.invert(T) for T in solved])
        fit, failed = calibctl_solve(T_base_gripper, T_board_cam)
        assert fit is not None, failed
        ours.append(errors(fit.T_a_b, X_GRIPPER_CAM))
        cases[f"robot{s}"] = cv4_case(T_base_gripper, T_board_cam)
    rows = {"calibctl park + joint refinement": ours}
    res = run_cv4(cv4, cases, 1)
    if res:
        for m in CV4_METHODS:
            rows[f"OpenCV {res['opencv_version']} {m}"] = [
                errors(np.array(res["cases"][k][m]["T_gripper_cam"]), X_GRIPPER_CAM) for k in cases
            ]
    out = [
        f"## 2. Robot arm on rendered photos ({scenes} scenes x 15 poses, 640x480, seed lens, camera on "
        "the gripper)",
        "",
        "Board poses: calibctl's detection + solvePnP on the true intrinsics, the same poses for every "
        "solver.",
        "",
        "| solver | worst rotation error deg | worst translation error mm | mean translation error mm |",
        "|---|---|---|---|",
    ]
    out += [
        f"| {n} | {max(e[0] for e in v):.4f} | {max(e[1] for e in v):.3f} | "
        f"{np.mean([e[1] for e in v]):.3f} |"
        for n, v in rows.items()
    ]
    return out + [""]


def section_degenerate(cv4: str | None) -> list[str]:
    logs = {
        "corridor (straight drive, +/-1 deg yaw)": synthesize_pose_log(
            X_TRUE, 30, excitation="corridor", noise_rotation_deg=0.05, noise_translation_m=0.002
        ),
        "planar (yaw only, +/-45 deg)": synthesize_pose_log(
            X_TRUE, 30, excitation="planar", noise_rotation_deg=0.05, noise_translation_m=0.002
        ),
        "3-D, b's clock 80 ms late": synthesize_pose_log(
            X_TRUE, 30, time_offset_s=0.08, noise_rotation_deg=0.05, noise_translation_m=0.002
        ),
    }
    keys = {name: f"deg{i}" for i, name in enumerate(logs)}
    res = run_cv4(cv4, {keys[n]: cv4_case(v.T_first, v.T_second) for n, v in logs.items()}, 1)
    out = [
        "## 3. Degenerate or unsynchronised logs: refused, or a number?",
        "",
        "| log | calibctl | "
        + " | ".join(f"OpenCV {m} (rot deg / trans mm error)" for m in ("PARK", "DANIILIDIS"))
        + " |",
        "|---|---|---|---|",
    ]
    for name, log in logs.items():
        fit, failed = calibctl_solve(log.T_first, log.T_second)
        ours = (
            "refused: " + "; ".join(failed)
            if fit is None
            else "{:.3f} deg / {:.1f} mm".format(*errors(fit.T_a_b, X_TRUE))
        )
        theirs = [
            "{:.2f} / {:.0f}".format(*errors(np.array(res["cases"][keys[name]][m]["T_gripper_cam"]), X_TRUE))
            if res
            else "-"
            for m in ("PARK", "DANIILIDIS")
        ]
        out.append(f"| {name} | {ours} | {' | '.join(theirs)} |")
    return out + [""]


def section_honesty(runs: int) -> list[str]:
    z = []
    for seed in range(runs):
        log = synthesize_motions(X_TRUE, 12, noise_rotation_deg=0.05, noise_translation_m=0.005, seed=seed)
        fit = fit_handeye(
            Motions.from_transforms(log.T_first, log.T_second, tuple(str(i) for i in range(12)))
        )
        z.append((fit.T_a_b[:3, 3] - X_TRUE[:3, 3]) / fit.sigma_translation_m)
    zz = np.array(z)
    out = [
        f"## 4. Is the lever-arm sigma honest? ({runs} runs x 12 independent motions, 30-60 deg, "
        "0.05 deg + 5 mm noise per motion)",
        "",
        "| axis | mean z | std z |",
        "|---|---|---|",
    ]
    out += [f"| {a} | {zz[:, i].mean():+.3f} | {zz[:, i].std():.3f} |" for i, a in enumerate("xyz")]
    out += [
        f"| all | {zz.mean():+.3f} | {zz.std():.3f} |",
        "",
        "The bar: mean within +/-0.3, std 0.7-1.5.",
        "",
    ]
    return out


def section_conditioning(trials: int) -> list[str]:
    rng = np.random.default_rng(7)
    out = [
        "## 5. The seed's conditioning table (planar, 1 cm of error in the motion translation)",
        "",
        "| rotation | 2 sin(theta/2) | seed's lever-arm error m | propagated sigma m | Monte Carlo std m |",
        "|---|---|---|---|---|",
    ]
    seed_column = {2: 0.287, 5: 0.115, 10: 0.057, 30: 0.019, 45: 0.013, 90: 0.007}
    for deg, quoted in seed_column.items():
        R = se3.rotation_from_rotvec(np.array([0.0, 0.0, np.radians(deg)]))
        predicted = lever_arm_sigma_m(R[None], 0.01)[0][0]
        draws = np.linalg.solve((R - np.eye(3))[:2, :2], rng.normal(0.0, 0.01, (2, trials))).T
        out.append(
            f"| {deg} deg | {2 * np.sin(np.radians(deg) / 2):.4f} | {quoted} | {predicted:.4f} | "
            f"{draws.std(axis=0).mean():.4f} |"
        )
    return out + [""]


def section_speed(repeats: int, cv4: str | None) -> list[str]:
    logs = {
        n: synthesize_pose_log(X_TRUE, n, noise_rotation_deg=0.05, noise_translation_m=0.002, seed=1)
        for n in (15, 200)
    }
    res = run_cv4(cv4, {f"speed{n}": cv4_case(v.T_first, v.T_second) for n, v in logs.items()}, repeats)
    out = [
        f"## 6. Speed of one solve (best of {repeats} in-process calls, ms)",
        "",
        "| poses | calibctl: gates + park + joint refinement + covariance + consistency and "
        "translation-scale gates | " + " | ".join(f"OpenCV {m}" for m in CV4_METHODS) + " |",
        "|---|---|" + "---|" * len(CV4_METHODS),
    ]
    for n, log in logs.items():
        best = float("inf")
        for _ in range(repeats):
            start = time.perf_counter()
            calibctl_solve(log.T_first, log.T_second)
            best = min(best, time.perf_counter() - start)
        theirs = [f"{res['cases'][f'speed{n}'][m]['best_s'] * 1e3:.2f}" if res else "-" for m in CV4_METHODS]
        out.append(f"| {n} | {best * 1e3:.2f} | {' | '.join(theirs)} |")
    return out + [
        "",
        "OpenCV pairs every pose with every other (n(n-1)/2 motions, so its time grows as n^2); calibctl's "
        "closed form uses the n-1 consecutive motions and its refinement the n poses (12 parameters, "
        "numerical Jacobian).",
        "",
    ]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=50, help="pose logs in section 1, runs x 6 in section 4")
    parser.add_argument("--scenes", type=int, default=5, help="rendered robot scenes in section 2")
    parser.add_argument("--repeats", type=int, default=20, help="timed calls per solver in section 6")
    parser.add_argument(
        "--opencv4-python",
        default=os.environ.get("CALIBCTL_OPENCV4_PYTHON"),
        help="interpreter with OpenCV 4.x (calibrateHandEye); env CALIBCTL_OPENCV4_PYTHON",
    )
    args = parser.parse_args()
    cv4 = args.opencv4_python if args.opencv4_python and Path(args.opencv4_python).exists() else None
    start = time.perf_counter()
    acc, res = section_accuracy(args.seeds, cv4)
    body = [
        *acc,
        *section_robot(args.scenes, cv4),
        *section_degenerate(cv4),
        *section_honesty(6 * args.seeds),
        *section_conditioning(20000),
        *section_speed(args.repeats, cv4),
    ]
    head = [
        "# bench_handeye",
        "",
        f"{dt.datetime.now(dt.UTC).isoformat(timespec='seconds')}; {cpu_model()}, nproc "
        f"{len(os.sched_getaffinity(0))}; "
        f"load average before {' '.join(f'{v:.2f}' for v in os.getloadavg())}; Python "
        f"{platform.python_version()}, "
        f"OpenCV {cv2.__version__} (calibctl), numpy {np.__version__}; OpenCV 4 for calibrateHandEye: "
        f"{res.get('opencv_version', 'not available')} (numpy {res.get('numpy_version', '-')})",
        "",
    ]
    print("\n".join([*head, *body, f"total {time.perf_counter() - start:.1f} s"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
