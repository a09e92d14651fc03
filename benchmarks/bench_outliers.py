"""Outlier flags and the two-camera check on clean rendered sessions, and the two-camera check on real photos.

Sessions: ``calibctl synth``'s "good" scenario (20 views, a random photometry per view as the synth
command renders them: blur 0.55-0.85 px, gain, illumination slope), seeds 0..N-1, detected by calibctl's
detector, solved with the production model (k1k2). Nothing in them is an outlier, so every flag is a false
alarm. Reported per resolution: views flagged by the pre-issue-8 rule (RMS above max(median + 3 MAD-sigma,
1.5 x median)) and by the current rule (calibctl.core.intrinsics.outliers), corners the corner rule removes,
and the two-camera check's ratio (calibctl.core.capture.camera_split; suspected from 1.4). Real photos:
opencv-left-right as one folder, left alone, right alone (calibctl's detector, model k1k2).
Detected corners are cached in benchmarks/out/outlier-sessions/ (git-ignored), so a re-run only solves.

Run: python benchmarks/bench_outliers.py [--sessions N] [--sizes 640x480,1280x960]   (default 30)
"""

from __future__ import annotations

import argparse
import os
import pickle
import platform
import sys
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model  # noqa: E402

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.capture.camera_split import TWO_CAMERA_RATIO, check_one_camera  # noqa: E402
from calibctl.core.capture.detect import detect_board  # noqa: E402
from calibctl.core.intrinsics.outliers import flag_outliers, solve_rejecting_corners  # noqa: E402
from calibctl.core.synth.pinhole import Photometry, PinholeCamera, render_background, render_view  # noqa: E402
from calibctl.core.synth.scenes import scenario_poses  # noqa: E402

BOARD = BoardSpec.chessboard(9, 6, 0.025)
REAL_BOARD = BoardSpec.chessboard(9, 6, 1.0)
VIEWS = 20
CACHE = Path(__file__).resolve().parent / "out" / "outlier-sessions"


def detected_session(
    size: tuple[int, int], seed: int
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """(object points, corners, ids) per detected view of one rendered session, cached on disk."""
    path = CACHE / f"{size[0]}x{size[1]}-{seed}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    camera = PinholeCamera.seed_reference(size)
    rng = np.random.default_rng(seed)
    poses = scenario_poses("good", camera, BOARD, VIEWS, rng)
    background = render_background(size, rng)
    obj, img, ids = [], [], []
    for T in poses:
        det, _ = detect_board(render_view(camera, BOARD, T, rng, Photometry.random(rng), background), BOARD)
        if det is not None:
            obj.append(BOARD.object_points()[det.corner_ids])
            img.append(det.corners_px)
            ids.append(det.corner_ids)
    CACHE.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps((obj, img, ids)))
    return obj, img, ids


def old_rule_flags(per_view_rms_px: np.ndarray) -> int:
    median = float(np.median(per_view_rms_px))
    mad = float(np.median(np.abs(per_view_rms_px - median)))
    return int(np.sum(per_view_rms_px > max(median + 3.0 * 1.4826 * mad, 1.5 * median)))


def run(size: tuple[int, int], sessions: int) -> list[str]:
    views = old = new = corners = suspected = 0
    ratios, split_ratios = [], []
    worst = (0.0, -1)
    for seed in range(sessions):
        obj, img, ids = detected_session(size, seed)
        rejection = solve_rejecting_corners(obj, img, size, "k1k2", ids)
        sol = rejection.solution
        views += sol.n_views
        old += old_rule_flags(sol.per_view_rms_px)
        new += len(flag_outliers(sol).outlier_views)
        corners += len(rejection.rejected)
        split = check_one_camera(rejection.kept(obj), rejection.kept(img), size, "k1k2")
        if split is not None:
            split_ratios.append(split.ratio)
            suspected += split.suspected
        ratio = sol.per_view_rms_px / np.median(sol.per_view_rms_px)
        ratios.append(ratio)
        worst = max(worst, (float(ratio.max()), seed))
    r = np.concatenate(ratios)
    return [
        f"| {size[0]}x{size[1]} | {sessions} | {views} | {old} ({100 * old / views:.1f} %) | "
        f"{new} ({100 * new / views:.1f} %) | {corners} | {np.quantile(r, 0.99):.2f} | {worst[0]:.2f} "
        f"(seed {worst[1]}) "
        f"| {max(split_ratios):.2f}, {suspected} suspected, {len(split_ratios)} of {sessions} judged |"
    ]


def real_two_camera_rows() -> list[str]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.datasets import LEFT_RIGHT

    rows = []
    for label, pattern in (
        ("left + right in one folder", "*.jpg"),
        ("left alone", "left*.jpg"),
        ("right alone", "right*.jpg"),
    ):
        obj, img = [], []
        for path in sorted(LEFT_RIGHT.glob(pattern)):
            det, _ = detect_board(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), REAL_BOARD)
            if det is not None:
                obj.append(REAL_BOARD.object_points()[det.corner_ids])
                img.append(det.corners_px)
        split = check_one_camera(obj, img, (640, 480), "k1k2")
        assert split is not None
        groups = f"{len(split.group_a)} / {len(split.group_b)}"
        rows.append(
            f"| {label} | {len(obj)} | {groups} | {split.holdout_rms_px[0]:.3f} / "
            f"{split.holdout_rms_px[1]:.3f} | "
            f"{split.cross_rms_px[0]:.3f} / {split.cross_rms_px[1]:.3f} | {split.ratio:.2f} | "
            f"{'two cameras' if split.suspected else 'one camera'} |"
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=30)
    parser.add_argument("--sizes", default="640x480,1280x960")
    args = parser.parse_args()
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    print(
        f"# bench_outliers: {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} cores ({cpu_model()}), "
        f"load {os.getloadavg()[0]:.1f}; Python {platform.python_version()}, OpenCV {cv2.__version__}\n"
    )
    print(
        "| size | sessions | views | views flagged, old rule | views flagged, calibctl | corners removed "
        "| per-view RMS / median, p99 | max | two-camera ratio: max, sessions suspected, judged |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for size in sizes:
        print("\n".join(run((size[0], size[1]), args.sessions)), flush=True)
    print(
        f"\nTwo-camera check on real photos (opencv-left-right; suspected from ratio {TWO_CAMERA_RATIO}):\n"
    )
    print("| folder | views | split | held-out RMS a / b, px | cross RMS a / b, px | ratio | verdict |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(real_two_camera_rows()))


if __name__ == "__main__":
    main()
