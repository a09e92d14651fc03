"""Model adequacy (lint rule model-misfit): fit RMS / detector RMS per model on real photos and renders.

Real photos: opencv-left-right (left, right) and udacity-camcal, detected as
tests/core/intrinsics/test_solve_real.py
does (plain findChessboardCorners + cornerSubPix). Renders: the seed pinhole lens (0.2 px noise) and
equidistant fisheye lenses (calibctl.core.synth.fisheye, 18 views, seed 2). Every solve runs the corner
rule first (calibctl.core.intrinsics.outliers), as `calibctl solve` does.

Run: python benchmarks/bench_model_misfit.py
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from calibctl.core.intrinsics.model_fit import MISFIT_RATIO, detector_rms_px  # noqa: E402
from calibctl.core.intrinsics.outliers import solve_rejecting_corners  # noqa: E402
from calibctl.core.synth.corners import synthesize_session  # noqa: E402
from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session  # noqa: E402
from tests.core.intrinsics.test_solve_real import _natural, detect_all, model_points  # noqa: E402
from tests.datasets import LEFT_RIGHT, UDACITY  # noqa: E402


def row(name: str, obj, img, size, model: str) -> None:
    r = solve_rejecting_corners(obj, img, size, model)
    d = detector_rms_px(r.kept(obj), r.kept(img))
    ratio = r.solution.rms_px / d
    print(
        f"| {name} | {model} | {r.solution.rms_px:.3f} | {d:.3f} | {ratio:.2f} | "
        f"{'fail' if ratio > MISFIT_RATIO and r.solution.rms_px - d > 0.3 else 'pass'} |",
        flush=True,
    )


def main() -> None:
    print("| set | model | fit RMS px | detector RMS px | ratio | model-misfit |\n|---|---|---|---|---|---|")
    for name, paths, size in (
        ("opencv-left-right left", sorted(LEFT_RIGHT.glob("left*.jpg"), key=_natural), (640, 480)),
        ("opencv-left-right right", sorted(LEFT_RIGHT.glob("right*.jpg"), key=_natural), (640, 480)),
        ("udacity-camcal", sorted(UDACITY.glob("calibration*.jpg"), key=_natural), (1280, 720)),
    ):
        views = detect_all(paths)
        for model in ("k1k2", "rational") if name == "udacity-camcal" else ("k1k2",):
            row(name, [model_points()] * len(views), [c for _, c, _ in views], size, model)
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    for seed in range(2):
        s = synthesize_session(K, np.array([-0.2814, 0.0977, 0, 0, 0]), (640, 480), 18, seed)
        row(
            f"pinhole render seed {seed}",
            list(s.object_points_per_view),
            list(s.image_points_per_view),
            (640, 480),
            "k1k2",
        )
    for fov, circular in ((120, False), (150, True), (170, True), (190, True), (150, False)):
        s = synthesize_fisheye_session(FisheyeCamera.from_fov((1280, 960), fov, circular), 18, 2)
        for model in ("k1k2", "fisheye"):
            row(
                f"fisheye {fov} deg {'circular' if circular else 'full-frame'}",
                list(s.object_points_per_view),
                list(s.image_points_per_view),
                (1280, 960),
                model,
            )


if __name__ == "__main__":
    main()
