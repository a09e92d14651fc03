"""A real 4-camera rig from video (caliscope-4cam): calibctl beside plain OpenCV and the recorder's result.

    .venv/bin/python benchmarks/bench_rig_caliscope.py [--runs 5:opencv-default:1=1,5:k1k2] [--out FILE]

Set: ../shared/datasets/caliscope-4cam (four 1280x720 webcams, 111 frames each as MP4, the recorder's
timestamps, an inverted 4 x 5-square ChArUco, DICT_4X4_1000, 54 mm squares, markers 0.75 of a square).

1. Detection, per camera over every frame: a plain ``cv2.aruco.CharucoDetector`` without and with
   ``detectInvertedMarker`` (frames with >= 4 corners, corners) beside calibctl's ``detect_board`` on the
   board declared inverted (>= 6 corners spanning two rows and columns).
2. calibctl: ``solve_rig_folders`` end to end on the four videos and timestamps.csv (decode, detect, pair by
   time within each run's tolerance, each member self-calibrated with its model, the rig gate, the joint LM,
   5-fold held-out residuals, every loop closure, the verdict).
3. Plain OpenCV: calibrateCamera (flags 0) per camera on the plain inverted detector's frames with >= 6
   corners, stereoCalibrate (CALIB_FIX_INTRINSIC) per pair on the frames of one sync_index (the recorder's
   own pairing), chained from camera 0 along the pairs with the most shared frames.
4. The recorder's camera_array.toml (caliscope's bundle adjustment: a peer's answer, not truth): relative
   poses T_0_c of all three routes compared (baseline, rotation, and the difference of the two poses).
5. Motion between exposures: calibctl's residual per camera view against the time spread of its rig frame.
6. Which frames belong together: plain stereo RMS per pair with camera b one frame earlier / as timestamped /
   one frame later (camera 1's video is one frame off its timestamps: the runs declare --frame-shift 1=+1),
   and with camera b's corners moved dt along their image motion (an exposure offset the timestamps miss).
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import os
import sys
import time
import tomllib
from pathlib import Path

import cv2
import numpy as np
from machine import cpu_model, load_1min  # benchmarks/machine.py (scripts run from benchmarks/)

from calibctl.core.board.board_spec import BoardSpec, make_charuco_board
from calibctl.core.board.views import BoardView
from calibctl.core.capture.detect import detect_board
from calibctl.core.extrinsics.rig_frame_shift import moved_corners
from calibctl.core.extrinsics.rig_problem import RigViews
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_tree import sigma_rotation_deg, sigma_translation_mm
from calibctl.core.extrinsics.rig_uncertainty import rig_covariance
from calibctl.core.extrinsics.se3 import invert, rotation_angle_deg
from calibctl.errors import CalibctlError
from calibctl.workflows.rig import rig_video
from calibctl.workflows.rig.rig_folders import (
    USABLE,
    calibrate_member,
    parse_exposure_offsets,
    parse_frame_shifts,
    rig_views,
    self_calibrated,
    solve_rig_folders,
)

DATASETS = Path(
    os.environ.get("CALIBCTL_TEST_DATASETS", Path(__file__).resolve().parents[2] / "shared" / "datasets")
)
if not DATASETS.is_dir():
    DATASETS = Path("/work/shared/datasets")
SET = DATASETS / "caliscope-4cam"
CAMS = ("0", "1", "2", "3")
BOARD = BoardSpec.charuco(4, 5, 0.054, 0.054 * 0.75, "DICT_4X4_1000", inverted=True)
IMAGE_SIZE = (1280, 720)
FPS = 6.0  # the recordings' frame rate (timestamps.csv: 166.7 ms apart)
Row = tuple[BoardView | None, ...]  # one rig frame: each camera's view
SHIFT = {"1": 1}  # camera 1's video is one frame off its timestamps (rig-frame-shift)


def _frames(cam: str) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(SET / "extrinsic" / f"cam_{cam}.mp4"))
    out = []
    while True:
        ok, image = capture.read()
        if not ok:
            break
        out.append(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    capture.release()
    return out


def _plain_detector(inverted: bool) -> cv2.aruco.CharucoDetector:
    params = cv2.aruco.DetectorParameters()
    params.detectInvertedMarker = inverted
    return cv2.aruco.CharucoDetector(make_charuco_board(BOARD), cv2.aruco.CharucoParameters(), params)


def detection(grays: dict[str, list[np.ndarray]]) -> tuple[list[dict[str, object]], dict]:
    """Per camera and detector: frames (>= 4 corners), corners, ms per frame; and the plain inverted views."""
    rows, views = [], {}
    for cam, frames in grays.items():
        for label, inverted in (("plain CharucoDetector", False), ("plain CharucoDetector, inverted", True)):
            detector = _plain_detector(inverted)
            start = time.perf_counter()
            found = [detector.detectBoard(g) for g in frames]
            ms = (time.perf_counter() - start) / len(frames) * 1e3
            kept = {
                i: (ids.ravel(), c.reshape(-1, 2))
                for i, (c, ids, _, _) in enumerate(found)
                if ids is not None
            }
            kept = {i: v for i, v in kept.items() if len(v[0]) >= 4}
            rows.append({"camera": cam, "detector": label, "frames": len(kept),
                         "corners": sum(len(v[0]) for v in kept.values()), "ms": ms})  # fmt: skip
            if inverted:
                views[cam] = kept
        start = time.perf_counter()
        found_c = [detect_board(g, BOARD)[0] for g in frames]
        ms = (time.perf_counter() - start) / len(frames) * 1e3
        hits = [d for d in found_c if d is not None]
        label = "calibctl detect_board (declared inverted)"
        corners = sum(len(d.corner_ids) for d in hits)
        rows.append({"camera": cam, "detector": label, "frames": len(hits), "corners": corners, "ms": ms})
    return rows, views


def recorder_poses() -> dict[str, np.ndarray]:
    """T_0_c from camera_array.toml (its rotation / translation are world-to-camera)."""
    doc = tomllib.loads((SET / "camera_array.toml").read_text())
    T_cam_world = {}
    for cam in CAMS:
        c = doc["cameras"][cam]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = np.array(c["rotation"]), np.array(c["translation"])
        T_cam_world[cam] = T
    return {cam: T_cam_world["0"] @ invert(T_cam_world[cam]) for cam in CAMS}


def _sync(shifts: dict[str, int]) -> dict[int, dict[str, int]]:
    """The recorder's own pairing: sync_index -> camera -> video frame (its frame k read with the time listed
    for k - shift, as --frame-shift reads it)."""
    with (SET / "extrinsic" / "timestamps.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    first = {cam: min(int(r["frame_index"]) for r in rows if r["cam_id"] == cam) for cam in CAMS}
    sync: dict[int, dict[str, int]] = {}
    for r in rows:
        cam = r["cam_id"]
        sync.setdefault(int(r["sync_index"]), {})[cam] = (
            int(r["frame_index"]) - first[cam] + shifts.get(cam, 0)
        )
    return sync


def _moved_corners(view_by_frame: dict, k: int, dt_s: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Frame k's corners moved dt_s later along their image velocity (core.extrinsics.rig_frame_shift,
    frames FPS apart); None without both neighbours."""
    if dt_s == 0.0:
        return view_by_frame.get(k)
    return moved_corners(view_by_frame, {j: j / FPS for j in (k - 1, k + 1)}, k, dt_s)


def _stereo(
    views: dict, intr: dict, sync: dict, a: str, b: str, dt_b_s: float = 0.0, moved_only: bool = False
):
    """stereoCalibrate (intrinsics fixed) of the pair on the given pairing; camera b's corners at dt_b_s."""
    obj = BOARD.object_points().astype(np.float32)
    objs, pts_a, pts_b = [], [], []
    for frames in sync.values():
        if a not in frames or b not in frames:
            continue
        va = views[a].get(frames[a])
        vb = (
            _moved_corners(views[b], frames[b], dt_b_s) if (dt_b_s or moved_only) else views[b].get(frames[b])
        )
        if moved_only and _moved_corners(views[b], frames[b], 1e-3) is None:
            vb = None
        if va is None or vb is None:
            continue
        common = np.intersect1d(va[0], vb[0])
        if len(common) < 6:
            continue
        objs.append(obj[common])
        pts_a.append(va[1][np.searchsorted(va[0], common)].astype(np.float32))
        pts_b.append(vb[1][np.searchsorted(vb[0], common)].astype(np.float32))
    if len(objs) < 3:
        return None
    out = cv2.stereoCalibrate(
        objs, pts_a, pts_b, *intr[a], *intr[b], IMAGE_SIZE, flags=cv2.CALIB_FIX_INTRINSIC
    )
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = out[5], np.ravel(out[6])
    return T, len(objs), out[0]  # T_b_a


def plain_opencv(views: dict, start: float, shifts: dict[str, int] | None = None) -> dict[str, object]:
    """calibrateCamera per camera, stereoCalibrate per pair on the recorder's sync_index (camera frames
    shifted by ``shifts``), chained from 0."""
    obj = BOARD.object_points().astype(np.float32)
    intr, rms = {}, {}
    for cam in CAMS:
        good = [v for v in views[cam].values() if len(v[0]) >= 6]
        obj_pts, img_pts = [obj[i] for i, _ in good], [c.astype(np.float32) for _, c in good]
        err, K, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, IMAGE_SIZE, None, None)
        intr[cam], rms[cam] = (K, dist), err
    sync = _sync(shifts or {})
    pairs = {}
    for a in CAMS:
        for b in CAMS:
            if a < b and (found := _stereo(views, intr, sync, a, b)) is not None:
                pairs[(a, b)] = found
    T_0: dict[str, np.ndarray] = {"0": np.eye(4)}
    while len(T_0) < len(CAMS):
        (a, b), (T, _, _) = max(
            ((p, v) for p, v in pairs.items() if (p[0] in T_0) != (p[1] in T_0)), key=lambda item: item[1][1]
        )
        if a in T_0:
            T_0[b] = T_0[a] @ invert(T)  # T_0_b = T_0_a T_a_b
        else:
            T_0[a] = T_0[b] @ T
    summary = {f"{a}-{b}": (n, r) for (a, b), (_, n, r) in pairs.items()}
    return {
        "T_0": T_0,
        "camera_rms": rms,
        "pairs": summary,
        "time_s": time.perf_counter() - start,
        "intr": intr,
    }


def timing_tables(views: dict, intr: dict, shifts: dict[str, int]) -> list[str]:
    """Per pair, plain stereo RMS (intrinsics fixed) (1) with camera b's frames one frame earlier / as the
    recorder pairs them / one later, and (2) with the declared shift, camera b's corners moved dt along
    their image velocity: the dt that fits best is the pair's exposure offset the timestamps miss."""
    lines = ["| pair a-b | b one frame earlier | as timestamped | b one frame later |", "|---|---|---|---|"]
    for a in CAMS:
        for b in CAMS:
            if a < b:
                rms = [_stereo(views, intr, _sync({b: s}), a, b) for s in (-1, 0, 1)]
                lines.append(
                    f"| {a}-{b} | " + " | ".join(f"{r[2]:.3f} px ({r[1]})" if r else "-" for r in rms) + " |"
                )
    sync = _sync(shifts)
    scan_ms = np.arange(-60.0, 61.0, 5.0)
    lines += [
        "",
        f"Declared shift {shifts}; camera b's corners moved by dt along their image velocity (frames with "
        "both neighbours seen):",
        "",
        "| pair a-b | frames | RMS at dt = 0 | best dt ms | RMS at best dt |",
        "|---|---|---|---|---|",
    ]
    for a in CAMS:
        for b in CAMS:
            if a < b:
                fits = [_stereo(views, intr, sync, a, b, dt / 1e3, moved_only=True) for dt in scan_ms]
                if any(f is None for f in fits):
                    continue
                best = int(np.argmin([f[2] for f in fits]))
                zero = fits[int(np.argmin(np.abs(scan_ms)))]
                lines.append(
                    f"| {a}-{b} | {zero[1]} | {zero[2]:.3f} | {scan_ms[best]:+.0f} | {fits[best][2]:.3f} |"
                )
    return lines


def calibctl_run(
    tolerance_ms: float, model: str, shifts: dict[str, int], offsets_ms: dict[str, float]
) -> dict[str, object]:
    start = time.perf_counter()
    sources = {cam: SET / "extrinsic" / f"cam_{cam}.mp4" for cam in CAMS}
    try:
        run = solve_rig_folders(sources, BOARD, model, timestamps=SET / "extrinsic" / "timestamps.csv",
                                time_tolerance_ms=tolerance_ms, frame_shifts=shifts,
                                exposure_offsets_ms=offsets_ms)  # fmt: skip
    except CalibctlError as exc:
        return {"refused": exc.message, "time_s": time.perf_counter() - start}
    elapsed = time.perf_counter() - start
    out: dict[str, object] = {"run": run, "time_s": elapsed, "model": model, "shifts": shifts}
    sol = run.solution
    if sol is not None:
        out["T_0"] = {cam: sol.T_a_b(0, sol.views.cameras.index(cam)) for cam in sol.views.cameras}
        ne = rig_covariance(
            sol.views, list(sol.members), sol.cam_poses, sol.board_poses, False
        ).normal_equations
        out["residuals"] = ne.residuals_px
    return out


def motion_table(result: dict[str, object]) -> list[str]:
    """RMS residual of camera views binned by their rig frame's time spread."""
    run = result["run"]
    sol = run.solution  # type: ignore[attr-defined]
    from calibctl.workflows.rig import rig_video

    times = rig_video.read_timestamps(SET / "extrinsic" / "timestamps.csv")
    first = {cam: min(times[cam]) for cam in CAMS}
    spreads = {}
    for key, photos in run.match.frames:  # type: ignore[attr-defined]
        shift = result["shifts"]
        ts = [
            times[cam][int(str(p).rsplit("#", 1)[1]) + first[cam] - shift.get(cam, 0)]  # type: ignore[attr-defined]
            for cam, p in photos.items()
        ]
        spreads[str(key)] = (max(ts) - min(ts)) * 1e3
    bins = [(0, 1), (1, 2), (2, 3), (3, 5), (5, 10), (10, 20), (20, 45)]
    lines = ["| frame spread ms | camera views | residual RMS px |", "|---|---|---|"]
    residuals = result["residuals"]
    for lo, hi in bins:
        res = [r for (f, _), r in residuals.items() if lo <= spreads[sol.views.frames[f]] < hi]  # type: ignore[index]
        if res:
            rms = float(np.sqrt(np.mean(np.sum(np.vstack(res) ** 2, axis=1))))
            lines.append(f"| {lo}-{hi} | {len(res)} | {rms:.3f} |")
    return lines


def bootstrap(result: dict[str, object], resamples: int, seed: int = 0) -> list[str]:
    """Frame bootstrap of the one-sigma: rig frames drawn with replacement, each member re-calibrated on its
    views in the drawn frames (the run's model), the rig re-solved; sd of T_0_c's baseline and rotation over
    the resamples against the sigma the same procedure reports on all rig frames."""
    run = result["run"]
    cams, spec = run.cameras, BOARD  # type: ignore[attr-defined]
    model = result["model"]
    by_path = {o.path: o for c in cams for o in run.outcomes[c]}  # type: ignore[attr-defined]
    # the rig rows as the run solved them (a declared exposure offset moves that camera's corners); the
    # members calibrate on their frames as detected
    frames = list(zip([p for _, p in run.match.frames], run.views.views, strict=True))  # type: ignore[attr-defined]

    def usable(o: object) -> bool:
        return o is not None and o.status in USABLE and o.corner_ids is not None  # type: ignore[attr-defined]

    def numbers(
        drawn: list[tuple[dict[str, str], Row]],
    ) -> list[tuple[float, float, float, float]]:
        views = {c: [by_path[p[c]] for p, _ in drawn if c in p and usable(by_path[p[c]])] for c in cams}
        members = [
            calibrate_member(c, [spec.object_points()[o.corner_ids] for o in vs], [o.corners_px for o in vs],
                             IMAGE_SIZE, str(model))[0]
            for c, vs in views.items()
        ]  # fmt: skip
        rows = tuple(row for _, row in drawn)
        sol = solve_rig(
            RigViews(cams, spec.object_points(), tuple(str(i) for i in range(len(drawn))), rows), members
        )
        out = []
        for c in range(1, len(cams)):
            T, cov = sol.T_a_b(c, 0), sol.pair_covariance(c, 0)
            out.append((float(np.linalg.norm(T[:3, 3]) * 1e3), rotation_angle_deg(T[:3, :3]),
                        sigma_translation_mm(cov, T[:3, 3]), sigma_rotation_deg(cov)))  # fmt: skip
        return out

    full = numbers(frames)
    rng = np.random.default_rng(seed)
    boot, skipped = [], 0
    for _ in range(resamples):
        try:
            boot.append(numbers([frames[i] for i in rng.integers(0, len(frames), len(frames))]))
        except CalibctlError:
            skipped += 1
    b = np.array(boot)  # (resamples, cameras - 1, 4)
    lines = [
        f"Frame bootstrap ({result['label']}): {len(boot)} resamples of the {len(frames)} rig frames "
        f"({skipped} refused), members re-calibrated each time.",
        "",
        "| pair | baseline mm | sigma reported | bootstrap sd | sd / sigma | rotation deg | sigma reported | "
        "bootstrap sd | sd / sigma |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for k, cam in enumerate(cams[1:]):
        base, rot, s_t, s_r = full[k]
        sd_t, sd_r = b[:, k, 0].std(ddof=1), b[:, k, 1].std(ddof=1)
        lines.append(
            f"| {cams[0]}-{cam} | {base:.1f} | {s_t:.2f} | {sd_t:.2f} | {sd_t / s_t:.2f} | {rot:.2f} | "
            f"{s_r:.3f} | {sd_r:.3f} | {sd_r / s_r:.2f} |"
        )
    return lines


def offset_scan(camera: str, offsets_ms: list[float], resamples: int, seed: int = 0) -> list[str]:
    """Camera ``camera``'s exposure offset from the data: the rig (opencv-default members self-calibrated
    once, camera 1's frame shift declared) solved with that camera's corners interpolated to its listed times
    at each offset; the joint RMS over the camera views every offset keeps, its minimum by a parabola through
    the lowest point and its neighbours, and the minimum's sd over a bootstrap of the rig frames (poses kept
    from each offset's solve)."""
    start = time.perf_counter()
    sources = {cam: SET / "extrinsic" / f"cam_{cam}.mp4" for cam in CAMS}
    timed = rig_video.capture_timed(sources, BOARD, SET / "extrinsic" / "timestamps.csv", 5.0, None, SHIFT)
    members = [self_calibrated(c, timed.cameras[c].outcomes, BOARD, "opencv-default")[0] for c in CAMS]
    per_view: list[dict[tuple[str, int], float]] = []  # (rig frame, camera) -> mean squared residual px^2
    for ms in offsets_ms:
        cap = rig_video.with_exposure_offsets(timed, {camera: ms / 1e3}) if ms else timed
        views = rig_views(CAMS, cap.match, {c: rig_video.rig_outcomes(cap, c) for c in CAMS}, BOARD)
        sol = solve_rig(views, members)
        views = sol.views  # the frames the solve kept
        residuals = rig_covariance(views, members, sol.cam_poses, sol.board_poses, False).normal_equations
        per_view.append(
            {
                (views.frames[f], c): float(np.mean(np.sum(r**2, axis=1)))
                for (f, c), r in residuals.residuals_px.items()
            }
        )
    common = sorted(set.intersection(*(set(v) for v in per_view)))
    frames = sorted({f for f, _ in common})
    by_frame = {f: [k for k in common if k[0] == f] for f in frames}

    def minimum(drawn: list[str]) -> tuple[float, np.ndarray]:
        keys = [k for f in drawn for k in by_frame[f]]
        ms2 = np.array([np.mean([v[k] for k in keys]) for v in per_view])
        i = int(np.clip(np.argmin(ms2), 1, len(offsets_ms) - 2))
        a, b, _ = np.polyfit(offsets_ms[i - 1 : i + 2], ms2[i - 1 : i + 2], 2)
        return float(-b / (2 * a)) if a > 0 else float(offsets_ms[int(np.argmin(ms2))]), np.sqrt(ms2)

    best, rms = minimum(frames)
    rng = np.random.default_rng(seed)
    boot = [
        minimum([frames[i] for i in rng.integers(0, len(frames), len(frames))])[0] for _ in range(resamples)
    ]
    lines = [
        f"Camera {camera}'s exposure offset from the data ({len(frames)} rig frames, {len(common)} camera "
        "views "
        f"kept at every offset; {time.perf_counter() - start:.1f} s):",
        "",
        "| offset ms | " + " | ".join(f"{ms:+g}" for ms in offsets_ms) + " |",
        "|---|" + "---|" * len(offsets_ms),
        "| joint RMS px | " + " | ".join(f"{r:.3f}" for r in rms) + " |",
        "",
        f"Minimum at {best:+.1f} ms; frame bootstrap ({resamples} resamples) sd {np.std(boot):.1f} ms "
        f"(5-95 %: {np.percentile(boot, 5):+.1f} .. {np.percentile(boot, 95):+.1f} ms).",
    ]
    return lines


def _compare(T: np.ndarray, ref: np.ndarray) -> tuple[float, float, float, float]:
    """baseline mm, rotation deg, |t - t_ref| mm, rotation between the two deg."""
    return (
        float(np.linalg.norm(T[:3, 3]) * 1e3),
        rotation_angle_deg(T[:3, :3]),
        float(np.linalg.norm(T[:3, 3] - ref[:3, 3]) * 1e3),
        rotation_angle_deg(T[:3, :3] @ ref[:3, :3].T),
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--runs",
        default="5:opencv-default:1=1:0~-28,5:opencv-default:1=1:2~30:3~25,5:opencv-default:1=1,5:k1k2:1=1:0~-28",
        help="TOLERANCE_MS:MODEL[:CAM=SHIFT][:CAM~MS] of each calibctl run (SHIFT: --frame-shift, "
        "MS: --exposure-offset)",
    )
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument(
        "--offset-scan",
        metavar="CAM",
        default=None,
        help="only scan camera CAM's exposure offset (-50..+10 ms) and estimate it with a bootstrap sd",
    )
    parser.add_argument(
        "--resamples", type=int, default=30, help="frame bootstrap of the first run (0: none)"
    )
    args = parser.parse_args()
    if not SET.is_dir():
        print(f"caliscope-4cam not found at {SET}", file=sys.stderr)
        return 2
    load = load_1min()
    if args.offset_scan is not None:
        head = (
            f"Measured {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC on {cpu_model()}, load {load:.1f} before."
        )
        text = "\n".join([head, "", *offset_scan(args.offset_scan, [float(ms) for ms in range(-50, 15, 5)],
                                                 max(args.resamples, 1))]) + "\n"  # fmt: skip
        print(text)
        if args.out is not None:
            args.out.write_text(text)
        return 0
    lines = [
        f"Measured {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC on {cpu_model()} (nproc {os.cpu_count()}), "
        f"load average {load:.1f} before the run, OpenCV {cv2.__version__}.",
        "",
    ]
    start = time.perf_counter()
    grays = {cam: _frames(cam) for cam in CAMS}
    decode_s = time.perf_counter() - start
    rows, views = detection(grays)
    del grays
    lines += ["| camera | detector | frames (>= 4 corners; calibctl >= 6) of 111 | corners | ms / frame |",
              "|---|---|---|---|---|"]  # fmt: skip
    lines += [
        f"| {r['camera']} | {r['detector']} | {r['frames']} | {r['corners']} | {r['ms']:.1f} |" for r in rows
    ]
    lines += ["", f"Decoding the 4 x 111 frames: {decode_s:.2f} s.", ""]
    recorder = recorder_poses()
    plain = plain_opencv(views, time.perf_counter())
    plain_shifted = plain_opencv(views, time.perf_counter(), SHIFT)
    runs = {}
    for item in args.runs.split(","):
        tol, model, *extra = item.split(":")
        shifts = parse_frame_shifts([e for e in extra if "~" not in e])
        offsets = parse_exposure_offsets([e.replace("~", "=") for e in extra if "~" in e])
        label = f"{float(tol):g} ms, {model}" + "".join(
            f", frame shift {c}={n:+d}" for c, n in shifts.items()
        )
        label += "".join(f", exposure offset {c}={ms:+g} ms" for c, ms in offsets.items())
        runs[label] = calibctl_run(float(tol), model, shifts, offsets)
    lines += [
        "| route | camera | baseline T_0_c mm | rotation deg | vs recorder: translation mm | rotation deg |",
        "|---|---|---|---|---|---|",
    ]
    for cam in CAMS[1:]:
        b, r, _, _ = _compare(recorder[cam], recorder[cam])
        lines.append(f"| recorder camera_array.toml | {cam} | {b:.1f} | {r:.2f} | - | - |")
    for label, route in (("", plain), (", camera 1 one frame later", plain_shifted)):
        for cam in CAMS[1:]:
            b, r, dt_mm, dr = _compare(route["T_0"][cam], recorder[cam])  # type: ignore[index]
            lines.append(
                f"| plain OpenCV (chained pairs{label}) | {cam} | {b:.1f} | {r:.2f} | {dt_mm:.1f} | "
                f"{dr:.2f} |"
            )
    for tol, result in runs.items():
        if "T_0" not in result:
            lines.append(f"| calibctl, {tol} | - | {result.get('refused', 'gate failed')} | | | |")
            continue
        sol = result["run"].solution  # type: ignore[attr-defined]
        for cam in CAMS[1:]:
            edge = next(e for e in sol.tree.edges if e.child == cam)
            b, r, dt_mm, dr = _compare(result["T_0"][cam], recorder[cam])  # type: ignore[index]
            lines.append(
                f"| calibctl, {tol} | {cam} | {b:.1f} +/- {edge.sigma_translation_mm:.1f} | "
                f"{r:.2f} +/- {edge.sigma_rotation_deg:.2f} | {dt_mm:.1f} | {dr:.2f} |"
            )
    lines += ["", "| route | per-camera RMS px (0 / 1 / 2 / 3) | time s |", "|---|---|---|"]
    doc = tomllib.loads((SET / "camera_array.toml").read_text())
    recorded = " / ".join(f"{doc['cameras'][c]['error']:.3f}" for c in CAMS)
    lines.append(f"| recorder (caliscope bundle adjustment) | {recorded} | - |")
    per_camera = " / ".join(f"{plain['camera_rms'][c]:.3f}" for c in CAMS)  # type: ignore[index]
    lines.append(
        f"| plain OpenCV calibrateCamera, per camera | {per_camera} | {plain['time_s']:.2f} (solves) |"
    )
    for label, route in (("", plain), (", camera 1 one frame later", plain_shifted)):
        stereo = route["pairs"].items()  # type: ignore[attr-defined]
        pair_rms = ", ".join(f"{p} {n} frames {r:.3f}" for p, (n, r) in stereo)
        lines.append(f"| plain OpenCV stereoCalibrate per pair{label} | {pair_rms} | |")
    detect_s = (
        sum(float(r["ms"]) for r in rows if r["detector"] == "plain CharucoDetector, inverted") * 111 / 1e3
    )
    lines.append(
        f"| plain OpenCV end to end (decode {decode_s:.2f} s, inverted detection {detect_s:.2f} s, solves) | "
        f"| {decode_s + detect_s + float(plain['time_s']):.2f} |"  # type: ignore[arg-type]
    )
    for tol, result in runs.items():
        if "run" not in result:
            continue
        run = result["run"]
        fitted = run.fits  # type: ignore[attr-defined]
        fits = " / ".join(f"{fitted[c].fit_rms_px:.3f}" for c in CAMS if c in fitted)
        sol = run.solution  # type: ignore[attr-defined]
        rig = " / ".join(f"{v:.3f}" for v in sol.rms_px) if sol else "-"
        lines.append(f"| calibctl {tol}: members self-calibrated | {fits} | {result['time_s']:.2f} (all) |")
        lines.append(f"| calibctl {tol}: rig joint LM | {rig} | |")
    for tol, result in runs.items():
        if "run" not in result:
            continue
        run = result["run"]
        t = run.timing  # type: ignore[attr-defined]
        failed = sorted({f.rule for f in run.findings if f.severity == "error"})  # type: ignore[attr-defined]
        shared = run.views.shared_view_counts().items()  # type: ignore[attr-defined]
        cams = run.cameras  # type: ignore[attr-defined]
        lines += [
            "",
            f"calibctl at {tol}: {t['rig_frames']} rig frames, {t['outside_tolerance']} frames outside, "
            f"spread median {t['spread_ms']['median']:.2f} ms, max {t['spread_ms']['max']:.2f} ms; "
            "shared views "
            + ", ".join(f"{cams[a]}-{cams[b]} {n}" for (a, b), n in shared)
            + f"; verdict {'pass' if run.passed else 'fail'} ({', '.join(failed)}).",  # type: ignore[attr-defined]
        ]
        for lc in run.loops:  # type: ignore[attr-defined]
            lines.append(
                f"- loop {'-'.join(lc.cycle)}: {lc.rotation_deg:.2f} deg "
                f"(sigma {lc.sigma_rotation_deg:.2f}), "
                f"{lc.translation_mm:.1f} mm (sigma {lc.sigma_translation_mm:.1f}), Mahalanobis "
                f"{lc.mahalanobis:.2f}"
            )
        if "residuals" in result:
            lines += ["", f"Residual against the rig frame's time spread (calibctl, {tol}):", ""]
            lines += motion_table(result)
    lines += [
        "",
        "Which frames belong together: plain stereo RMS per pair (intrinsics fixed, frames counted):",
        "",
    ]
    lines += timing_tables(views, plain["intr"], SHIFT)  # type: ignore[arg-type]
    first_label, first = next(iter(runs.items()))
    if args.resamples > 0 and first.get("run") is not None and first["run"].solution is not None:  # type: ignore[attr-defined]
        first["label"] = first_label
        lines += ["", *bootstrap(first, args.resamples)]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out is not None:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
