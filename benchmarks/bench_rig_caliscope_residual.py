"""What is left of caliscope-4cam's joint residual once camera 1's frame shift and camera 0's exposure offset
are declared (0.44-0.55 px per camera, each camera alone 0.13-0.19 px): the candidate causes, one at a time.

    cd benchmarks && ../.venv/bin/python bench_rig_caliscope_residual.py [--out FILE]

The rig is solved as ``bench_rig_caliscope.py``'s first run (5 ms, opencv-default, ``--frame-shift 1=+1
--exposure-offset 0=-28``) with the intrinsics fixed and freed; each corner's rig residual (observed -
projected) is set beside its image row, its image velocity (its own camera's frames k - 1 and k + 1, the
board's corners as calibctl detects them, over their listed times) and the member's principal point.

1. Motion: the residual binned by the corner's image speed.
2. Rolling shutter: per camera one line delay fitted to residual = delay * (row - the view's mean row) *
   velocity (a row-proportional ramp along the motion; the view's mean part is what the board pose absorbs).
3. What shape the residual has within one camera view: one parameter per view fitted to its corners (a time
   along the corners' velocity, a scale or a rotation about the principal point, the rolling-shutter shear,
   a control direction: the velocity turned 90 deg) and the view's mean shift (two parameters); views whose
   corners all have a velocity.
4. The lens: the rig re-solved with every member's intrinsics free (``solve_rig(refine_intrinsics=True)``).
5. A bowed board: the rig re-solved with the board's model points bowed (core.intrinsics.board_warp, two
   parabolic cylinders of w_x, w_y metres), intrinsics fixed.
6. The recorder's timestamps against a steady clock per camera (a linear fit over the frame index): does the
   per-view time of 3. follow their jitter?
"""

from __future__ import annotations

import argparse
import datetime as dt
import sys
import time
from pathlib import Path

import numpy as np
from bench_rig_caliscope import BOARD, CAMS, SET, SHIFT
from machine import cpu_model, load_1min  # benchmarks/machine.py (scripts run from benchmarks/)

from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_uncertainty import rig_covariance
from calibctl.core.extrinsics.rig_validation import RigHoldout
from calibctl.core.intrinsics.board_warp import bowed_points
from calibctl.workflows.rig import rig_video
from calibctl.workflows.rig.rig_folders import solve_rig_folders

OFFSETS_MS = {"0": -28.0}
TIMES = SET / "extrinsic" / "timestamps.csv"
Residuals = dict[tuple[int, int], np.ndarray]
Views = dict[int, tuple[np.ndarray, np.ndarray]]  # video frame index -> (sorted corner ids, (N, 2) px)


def _raw(cam: str) -> tuple[Views, dict[int, float]]:
    """Camera ``cam``'s detected corners and listed times per video frame (the frame label's number)."""
    frames = rig_video.detect_camera(cam, SET / "extrinsic" / f"cam_{cam}.mp4", BOARD)
    listed = rig_video.read_timestamps(TIMES)[cam]
    first = min(listed)
    views: Views = {}
    times: dict[int, float] = {}
    for o in frames.outcomes:
        idx = int(o.name.rsplit("#", 1)[1])
        if idx + first - SHIFT.get(cam, 0) in listed:
            times[idx] = listed[idx + first - SHIFT.get(cam, 0)]
        if o.corner_ids is not None and o.corners_px is not None and len(o.corner_ids) >= 6:
            order = np.argsort(o.corner_ids)
            views[idx] = (np.asarray(o.corner_ids)[order], np.asarray(o.corners_px)[order])
    return views, times


def _velocity(raw: tuple[Views, dict[int, float]], idx: int, ids: np.ndarray) -> np.ndarray:
    """(N, 2) px/s of corners ``ids`` at video frame ``idx`` from frames idx - 1 and idx + 1 (nan without)."""
    views, times = raw
    out = np.full((len(ids), 2), np.nan)
    before, after = views.get(idx - 1), views.get(idx + 1)
    if before is None or after is None or idx - 1 not in times or idx + 1 not in times:
        return out
    span_s = times[idx + 1] - times[idx - 1]
    for n, i in enumerate(ids):
        if span_s > 0 and i in before[0] and i in after[0]:
            out[n] = (
                after[1][np.searchsorted(after[0], i)] - before[1][np.searchsorted(before[0], i)]
            ) / span_s
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(x**2, axis=1)))) if len(x) else float("nan")


def _solve(
    views: RigViews, members: list[MemberIntrinsics], refine: bool
) -> tuple[RigViews, Residuals, list]:
    sol = solve_rig(views, members, refine_intrinsics=refine, model="opencv-default")
    ne = rig_covariance(sol.views, list(sol.members), sol.cam_poses, sol.board_poses, False).normal_equations
    return sol.views, ne.residuals_px, list(sol.members)


def _per_camera(views: RigViews, res: Residuals) -> str:
    cams = [_rms(np.vstack([r for (_, c), r in res.items() if c == k])) for k in range(len(views.cameras))]
    return " / ".join(f"{x:.3f}" for x in cams)


def _table(views: RigViews, res: Residuals, labels: dict, raw: dict) -> np.ndarray:
    """One row per corner: camera, frame, row px, column px, residual x y px, velocity x y px/s."""
    rows = []
    for (f, c), r in res.items():
        v = views.views[f][c]
        assert v is not None
        vel = _velocity(raw[views.cameras[c]], labels[(views.frames[f], views.cameras[c])], v.corner_ids)
        for n in range(len(v.corner_ids)):
            rows.append((c, f, *v.corners_px[n, ::-1], *r[n], *vel[n]))
    return np.array(rows, dtype=float)


def motion_lines(t: np.ndarray) -> list[str]:
    speed = np.hypot(t[:, 6], t[:, 7])
    lines = ["| corner image speed px/s | corners | residual RMS px |", "|---|---|---|"]
    for lo, hi in ((0, 20), (20, 40), (40, 70), (70, 150), (150, 1e9)):
        m = (speed >= lo) & (speed < hi)
        lines.append(f"| {lo:g}-{hi:g} | {m.sum()} | {_rms(t[m][:, 4:6]):.3f} |".replace("1e+09", "up"))
    m = ~np.isfinite(speed)
    lines.append(f"| no neighbouring frames | {m.sum()} | {_rms(t[m][:, 4:6]):.3f} |")
    return lines


def line_delay_lines(t: np.ndarray, cameras: tuple[str, ...]) -> list[str]:
    lines = ["| camera | line delay ms per frame (720 rows) | RMS px before | after |", "|---|---|---|---|"]
    for c, cam in enumerate(cameras):
        m = (t[:, 0] == c) & np.isfinite(t[:, 6])
        parts = []
        for f in np.unique(t[m, 1]):
            s = m & (t[:, 1] == f)
            g = (t[s, 2] - t[s, 2].mean())[:, None] * t[s][:, 6:8]
            parts.append((g, t[s][:, 4:6]))
        delay = sum(np.sum(g * r) for g, r in parts) / sum(np.sum(g * g) for g, _ in parts)
        after = np.vstack([r - delay * g for g, r in parts])
        lines.append(f"| {cam} | {delay * 720e3:+.1f} | {_rms(np.vstack([r for _, r in parts])):.3f} | "
                     f"{_rms(after):.3f} |")  # fmt: skip
    return lines


def view_shape(
    t: np.ndarray, members: list[MemberIntrinsics]
) -> tuple[list[str], dict[tuple[int, int], float]]:
    """Table 3 and each view's fitted time along its velocity (s)."""
    sums: dict[str, float] = {}
    times: dict[tuple[int, int], float] = {}
    n = 0
    for c, m in enumerate(members):
        cx, cy = m.camera_matrix[0, 2], m.camera_matrix[1, 2]
        for f in np.unique(t[t[:, 0] == c, 1]):
            s = (t[:, 0] == c) & (t[:, 1] == f)
            if not np.isfinite(t[s, 6]).all():
                continue
            r, vel = t[s][:, 4:6], t[s][:, 6:8]
            p = np.stack([t[s, 3] - cx, t[s, 2] - cy], 1)
            shapes = {
                "none": None,
                "a time along the corners' velocity": vel,
                "scale about the principal point": p,
                "rotation about the principal point": np.stack([-p[:, 1], p[:, 0]], 1),
                "rolling-shutter shear (row x velocity)": (t[s, 2] - t[s, 2].mean())[:, None] * vel,
                "control: the velocity turned 90 deg": np.stack([-vel[:, 1], vel[:, 0]], 1),
            }
            for name, g in shapes.items():
                a = 0.0 if g is None else np.sum(g * r) / np.sum(g * g)
                sums[name] = sums.get(name, 0.0) + float(np.sum((r - (0 if g is None else a * g)) ** 2))
                if name == "a time along the corners' velocity":
                    times[(c, int(f))] = a
            sums["the view's mean shift (2 parameters)"] = sums.get(
                "the view's mean shift (2 parameters)", 0.0
            ) + (float(np.sum((r - r.mean(0)) ** 2)))
            n += int(s.sum())
    lines = [f"| per-view fit ({len(times)} views, {n} corners) | residual RMS px left |", "|---|---|"]
    lines += [f"| {name} | {np.sqrt(v / n):.3f} |" for name, v in sums.items()]
    sd = np.std(list(times.values())) * 1e3
    lines.append(f"\nPer-view time along the velocity: sd {sd:.1f} ms over the views.")
    return lines, times


def view_shift_lines(t: np.ndarray, views: RigViews, labels: dict) -> list[str]:
    """Each camera view's mean residual (its whole-view shift): against the view's speed, and against the
    next video frame's of the same camera (a bumped camera drifts; a timing jitter does not)."""
    shift, speed = {}, {}
    for c, cam in enumerate(views.cameras):
        for f in np.unique(t[t[:, 0] == c, 1]):
            s = (t[:, 0] == c) & (t[:, 1] == f)
            idx = labels[(views.frames[int(f)], cam)]
            shift[(c, idx)] = t[s][:, 4:6].mean(0)
            speed[(c, idx)] = float(np.linalg.norm(t[s][:, 6:8].mean(0)))
    lines = ["| camera view speed px/s | views | whole-view shift RMS px |", "|---|---|---|"]
    for lo, hi in ((0, 20), (20, 40), (40, 70), (70, 150), (150, 1e9)):
        m = [k for k, v in speed.items() if lo <= v < hi]
        if m:
            lines.append(f"| {lo:g}-{hi:g} | {len(m)} | {_rms(np.array([shift[k] for k in m])):.3f} |")
    lines[-1] = lines[-1].replace("-1e+09", " and up")
    nan = [k for k, v in speed.items() if not np.isfinite(v)]
    lines.append(f"| no neighbouring frames | {len(nan)} | {_rms(np.array([shift[k] for k in nan])):.3f} |")
    pairs = np.array([(shift[(c, i)], shift[(c, i + 1)]) for c, i in shift if (c, i + 1) in shift])
    corr = [np.corrcoef(pairs[:, 0, k], pairs[:, 1, k])[0, 1] for k in (0, 1)]
    lines.append(f"\nWhole-view shifts of consecutive video frames of one camera ({len(pairs)} pairs): "
                 f"correlation {corr[0]:+.2f} in x, {corr[1]:+.2f} in y.")  # fmt: skip
    return lines


def bow_lines(views: RigViews, members: list[MemberIntrinsics]) -> list[str]:
    lines = ["| w_x mm | w_y mm | joint RMS px per camera (0 / 1 / 2 / 3) |", "|---|---|---|"]
    for wx, wy in ((0, 0), (-1, 0), (-0.25, 0), (0.25, 0), (1, 0), (0, -1), (0, -0.25), (0, 0.25), (0, 1)):
        pts = bowed_points([views.model_points_m], np.array([wx, wy]) * 1e-3)[0]
        v, res, _ = _solve(RigViews(views.cameras, pts, views.frames, views.views), members, False)
        lines.append(f"| {wx:+g} | {wy:+g} | {_per_camera(v, res)} |")
    return lines


def clock_lines(views: RigViews, labels: dict, fitted: dict[tuple[int, int], float]) -> list[str]:
    listed = rig_video.read_timestamps(TIMES)
    jitter: dict[str, dict[int, float]] = {}
    lines = ["| camera | listed time - steady clock: sd ms | max ms |", "|---|---|---|"]
    for cam in CAMS:
        k = np.array(sorted(listed[cam]), dtype=float)
        tt = np.array([listed[cam][int(i)] for i in k])
        a = np.stack([np.ones_like(k), k], 1)
        e = tt - a @ np.linalg.lstsq(a, tt, rcond=None)[0]
        jitter[cam] = {int(i): float(x) for i, x in zip(k, e, strict=True)}
        lines.append(f"| {cam} | {e.std() * 1e3:.1f} | {abs(e).max() * 1e3:.1f} |")
    first = {cam: min(listed[cam]) for cam in CAMS}
    pairs = []
    for (c, f), t_s in fitted.items():
        here = {}
        for cam in views.cameras:
            idx = labels.get((views.frames[f], cam))
            if idx is not None and idx + first[cam] - SHIFT.get(cam, 0) in jitter[cam]:
                here[cam] = jitter[cam][idx + first[cam] - SHIFT.get(cam, 0)]
        cam = views.cameras[c]
        if cam in here and len(here) > 1:
            pairs.append((t_s, -(here[cam] - np.mean([x for k, x in here.items() if k != cam]))))
    p = np.array(pairs)
    lines.append(
        f"\nA view's fitted time against its listed time's jitter relative to the rig frame's other cameras "
        f"({len(p)} views): correlation {np.corrcoef(p[:, 0], p[:, 1])[0, 1]:+.2f}; relative jitter sd "
        f"{p[:, 1].std() * 1e3:.1f} ms, fitted time sd {p[:, 0].std() * 1e3:.1f} ms."
    )
    return lines


def _epipolar(holdout: RigHoldout | None) -> str:
    if holdout is None:
        return "-"
    rms = [p.epipolar_rms_px for p in holdout.pairs if p.epipolar_rms_px is not None]
    return f"{min(rms):.2f}-{max(rms):.2f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    if not SET.is_dir():
        print(f"caliscope-4cam not found at {SET}", file=sys.stderr)
        return 2
    load, start = load_1min(), time.perf_counter()
    sources = {cam: SET / "extrinsic" / f"cam_{cam}.mp4" for cam in CAMS}
    run = solve_rig_folders(sources, BOARD, "opencv-default", timestamps=TIMES, time_tolerance_ms=5,
                            frame_shifts=SHIFT, exposure_offsets_ms=OFFSETS_MS)  # fmt: skip
    freed_run = solve_rig_folders(sources, BOARD, "opencv-default", timestamps=TIMES, time_tolerance_ms=5,
                                  frame_shifts=SHIFT, exposure_offsets_ms=OFFSETS_MS,
                                  refine_intrinsics=True)  # fmt: skip
    assert run.solution is not None
    raw = {cam: _raw(cam) for cam in CAMS}
    labels = {
        (str(key), cam): int(str(p).rsplit("#", 1)[1])
        for key, ps in run.match.frames
        for cam, p in ps.items()
    }
    members = list(run.solution.members)
    views, res, _ = _solve(run.solution.views, members, False)
    free_views, free_res, freed = _solve(run.solution.views, members, True)
    t, t_free = _table(views, res, labels, raw), _table(free_views, free_res, labels, raw)
    shape, fitted = view_shape(t, members)
    shape_free, _ = view_shape(t_free, freed)
    holdout = run.holdout
    lines = [
        f"Measured {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC on {cpu_model()}, load {load:.1f} before.",
        "",
        "1. Residual against the corner's image speed (intrinsics fixed / freed):",
        "",
        *motion_lines(t),
        "",
        *motion_lines(t_free),
        "",
        "2. One line delay per camera (rolling shutter), intrinsics fixed:",
        "",
        *line_delay_lines(t, views.cameras),
        "",
        "3. The shape of the residual within a camera view (intrinsics fixed / freed):",
        "",
        *shape,
        "",
        *shape_free,
        "",
        "The whole-view shift (intrinsics fixed) against the view's speed and the next frame's:",
        "",
        *view_shift_lines(t, views, labels),
        "",
        f"4. The lens: joint RMS per camera (0 / 1 / 2 / 3) with the intrinsics fixed "
        f"{_per_camera(views, res)}, freed {_per_camera(free_views, free_res)} px; held-out epipolar RMS per "
        f"pair {_epipolar(run.holdout)} fixed, {_epipolar(freed_run.holdout)} px freed.",
        "",
        "5. A bowed board (intrinsics fixed):",
        "",
        *bow_lines(views, members),
        "",
        "6. The listed times against a steady clock per camera:",
        "",
        *clock_lines(views, labels, fitted),
        "",
        f"Held-out camera RMS with intrinsics fixed (the run's): "
        f"{' / '.join(f'{x:.3f}' for x in holdout.camera_rms_px) if holdout else '-'} px. "
        f"Total {time.perf_counter() - start:.1f} s.",
    ]
    print("\n".join(lines))
    if args.out:  # the tables as printed, for benchmarks/results
        args.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
