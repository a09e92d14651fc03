"""The changed-camera test (core/intrinsics/camera_change.py): false refusals on clean sessions, catches.

Renders through the real detector (the seed lens at 640x480, 9x6 chessboard, scenario "good", 20 views in
capture order, photometry random), seeds 100 + i:
  clean: one camera throughout;
  focal +0.5 / +1 / +1.5 %: fx and fy of the views from the step on (at view 10) scaled;
  centre +3 px: cx (even seeds) or cy (odd seeds) of the views from view 10 on moved by 3 px.
Real sets: the corners calibctl detects in opencv-left-right left and right (13 views each), udacity-camcal
(17 views) and baka-stereo left / right, views in file-name order (the order they were taken).

Printed per case: sessions, how many the test calls changed, and the scan / judge statistics' spread.

Run: python benchmarks/bench_camera_change.py [N_CLEAN] [N_STEP]   (default 60 10; from the repository root)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent.parent))
from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.intrinsics.camera_change import judge_change  # noqa: E402
from calibctl.core.intrinsics.solve import solve_intrinsics  # noqa: E402
from tests.workflows.sessions import CHANGE_BOARD as BOARD  # noqa: E402
from tests.workflows.sessions import CHANGE_SIZE as SIZE  # noqa: E402
from tests.workflows.sessions import rendered_session  # noqa: E402


def judged(obj, img, size, model="k1k2"):
    sol = solve_intrinsics(obj, img, size, model)
    return judge_change(sol, obj, img, size)


def case(name: str, sessions) -> None:
    verdicts = [judged(*s, SIZE) for s in sessions]
    scored = [v for v in verdicts if v is not None]
    changed = sum(v.changed for v in scored)
    chi2 = np.array([v.chi2 for v in scored])
    steps = np.array([100 * v.focal_step for v in scored])
    centres = np.array([v.centre_step_px for v in scored])
    print(
        f"| {name} | {len(sessions)} | {changed} | median {np.median(chi2):.1f}, max {chi2.max():.1f}, "
        f"min {chi2.min():.1f} | {np.median(np.abs(steps)):.2f} | {np.median(centres):.2f} |"
    )


def real() -> None:
    from bench_diff import detected  # noqa: PLC0415  (benchmarks/ scripts import each other)

    from tests.core.intrinsics.test_solve_real import _natural  # noqa: PLC0415
    from tests.datasets import BAKA_STEREO, LEFT_RIGHT, UDACITY  # noqa: PLC0415

    baka = BoardSpec.chessboard(7, 10, 0.023)
    sets = [
        ("opencv-left-right left", sorted(LEFT_RIGHT.glob("left*.jpg")), BOARD),
        ("opencv-left-right right", sorted(LEFT_RIGHT.glob("right*.jpg")), BOARD),
        ("udacity-camcal", sorted(UDACITY.glob("calibration*.jpg"), key=_natural), BOARD),
        ("baka-stereo left", sorted((BAKA_STEREO / "left").glob("*.jpg"), key=_natural), baka),
        ("baka-stereo right", sorted((BAKA_STEREO / "right").glob("*.jpg"), key=_natural), baka),
    ]
    import cv2  # noqa: PLC0415

    for name, paths, board in sets:
        views = detected(paths, board)
        if len(views) < 10:
            print(f"| {name} | - | - | {len(views)} views detected | | |")
            continue
        size = cv2.imread(str(paths[0])).shape[1::-1]
        v = judged([a for a, _ in views], [b for _, b in views], tuple(size))
        if v is None:
            print(f"| {name} ({len(views)} views) | 1 | not judged | | | |")
            continue
        print(
            f"| {name} ({len(views)} views) | 1 | {int(v.changed)} | {v.chi2:.1f} (split at {v.split}) | "
            f"{100 * v.focal_step:+.2f} | {v.centre_step_px:.2f} |"
        )


if __name__ == "__main__":
    n_clean = int(sys.argv[1]) if len(sys.argv) > 1 else 60
    n_step = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    print("| case | sessions | called changed | chi2 | median abs focal step % | median centre step px |")
    print("|---|---|---|---|---|---|")
    case("clean", [rendered_session(100 + i) for i in range(n_clean)])
    for focal in (0.005, 0.01, 0.015):
        case(f"focal +{100 * focal:g} %", [rendered_session(200 + i, focal) for i in range(n_step)])
    case(
        "centre +3 px",
        [rendered_session(300 + i, 0.0, (3.0, 0.0) if i % 2 == 0 else (0.0, 3.0)) for i in range(n_step)],
    )
    if "--real" in sys.argv or len(sys.argv) <= 1:
        real()
