"""What the decisive capture gate blames on the real sets (core/capture/projection_gate.py ``cause_first``).

For each real set (the corners calibctl detects, views in file-name order) and lens model (k1k2, as a default
``calibrate`` asks; none, as a plain ``capture`` chooses between k1k2 and fisheye): the gate's worst
one-sigma over the image with the Jacobian covariance (what it judges) and with the covariance calibctl
reports (view-level where that rule fires), its verdict at 5 px, and the reason and first words of the hint
once ``cause_first`` has looked for a lens-model misfit or a camera that changed during the session.

Run: python benchmarks/bench_gate_cause.py   (from the repository root; needs ../shared/datasets)
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent.parent))
from bench_diff import detected  # noqa: E402  (benchmarks/ scripts import each other)

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.capture.projection_gate import (  # noqa: E402
    PROJECTION_SIGMA_MAX_PX,
    Region,
    cause_first,
    projection_gate,
    solve_for_gate,
)
from calibctl.core.intrinsics.report_maps import projection_uncertainty  # noqa: E402
from calibctl.core.intrinsics.solve import IntrinsicsSolution  # noqa: E402
from calibctl.errors import NumericalError  # noqa: E402
from tests.core.intrinsics.test_solve_real import _natural  # noqa: E402
from tests.datasets import BAKA_STEREO, DATASETS, LEFT_RIGHT, UDACITY  # noqa: E402

B9 = BoardSpec.chessboard(9, 6, 0.025)
BAKA = BoardSpec.chessboard(7, 10, 0.023)
SETS = [
    (
        "acfr-lidar-camera",
        sorted((DATASETS / "acfr-lidar-camera" / "images").glob("*.png"), key=_natural),
        None,
    ),
    ("baka-stereo left", sorted((BAKA_STEREO / "left").glob("*.jpg"), key=_natural), BAKA),
    ("baka-stereo right", sorted((BAKA_STEREO / "right").glob("*.jpg"), key=_natural), BAKA),
    ("udacity-camcal", sorted(UDACITY.glob("calibration*.jpg"), key=_natural), B9),
    ("opencv-left-right left", sorted(LEFT_RIGHT.glob("left*.jpg")), B9),
    ("opencv-left-right right", sorted(LEFT_RIGHT.glob("right*.jpg")), B9),
]


def reported_worst(sol: IntrinsicsSolution, size: tuple[int, int]) -> float:
    """The gate's worst sigma over the image with the reported covariance instead of the Jacobian one."""
    cov = sol.covariance
    assert cov is not None and cov.covariance is not None
    grid = (max(16, round(size[0] / 20)), max(12, round(size[1] / 20)))
    umap = projection_uncertainty(
        sol.camera_matrix,
        sol.dist_coeffs,
        cov.covariance,
        cov.names,
        sol.aspect_ratio,
        size,
        grid,
        fisheye=sol.model == "fisheye",
        rotation_fit=np.ones((grid[1], grid[0]), bool),
    )
    return float(np.nanmax(umap.sigma_px))


def main() -> None:
    print(
        "| set | views | model | worst sigma, Jacobian (judged) | reported | verdict at 5 px | reason "
        "| hint |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, paths, board in SETS:
        views = detected(paths, board or BoardSpec.chessboard(5, 7, 0.095))
        size = tuple(cv2.imread(str(paths[0])).shape[1::-1])
        obj, img = [a for a, _ in views], [b for _, b in views]
        for model in ("k1k2", None):
            try:
                sol: IntrinsicsSolution | NumericalError = solve_for_gate(obj, img, size, model)
            except NumericalError as exc:
                sol = exc
            gate = projection_gate(sol, size, Region("image"), PROJECTION_SIGMA_MAX_PX)
            named = cause_first(gate, sol, obj, img, size, Region("image"), PROJECTION_SIGMA_MAX_PX)
            reported = reported_worst(sol, size) if isinstance(sol, IntrinsicsSolution) else float("nan")
            chosen = getattr(sol, "model", "-")
            hint = " ".join((named.hint or "").split()[:9])
            print(
                f"| {name} | {len(views)} | {model or 'none'} ({chosen}) | {gate.value:.2f} | "
                f"{reported:.2f} | "
                f"{'pass' if gate.passed else 'FAIL'} | {named.reason or '-'} | {hint} |"
            )


if __name__ == "__main__":
    main()
