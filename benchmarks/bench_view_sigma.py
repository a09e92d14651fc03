"""The view-level sigma check (core/intrinsics/covariance.py): where it fires and what it does to z.

1. Renders through the real detector: the seed lens at 640x480, 9x6 chessboard, scenario "good", 20 views,
   seeds 100 + i, k1k2. Per session sigma_factor and whether the rule fired; over the sessions the z sd of
   every parameter with the Jacobian sigma (before) and the reported sigma (after). No per-view error here,
   so the rule should not fire.
2. opencv-left-right left (real, 13 views, k1k2): sigma_factor, and a delete-one jackknife over the views
   against the Jacobian sigma, per parameter.
3. The same views split at random 7 + 6 (40 splits, seed 0): sigma_factor of each half.

Run: python benchmarks/bench_view_sigma.py [N_RENDER_SESSIONS]   (default 20; from the repository root)
Measured numbers: docs/verdicts.md "Sigmas that hold on real data".
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_diff import LEFT_RIGHT, detected  # noqa: E402  (benchmarks/ scripts import each other)

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.capture.detect import detect_board  # noqa: E402
from calibctl.core.intrinsics.covariance import MAX_SIGMA_FACTOR  # noqa: E402
from calibctl.core.intrinsics.solve import IntrinsicsSolution, solve_intrinsics  # noqa: E402
from calibctl.core.synth.pinhole import Photometry, PinholeCamera, render_view  # noqa: E402
from calibctl.core.synth.scenes import scenario_poses  # noqa: E402

BOARD = BoardSpec.chessboard(9, 6, 0.025)
SIZE = (640, 480)


def _values(sol: IntrinsicsSolution) -> dict[str, float]:
    return {
        "fx": sol.fx,
        "fy": sol.fy,
        "cx": sol.cx,
        "cy": sol.cy,
        "k1": float(sol.dist_coeffs[0]),
        "k2": float(sol.dist_coeffs[1]),
    }


def _solve(views: list) -> IntrinsicsSolution:
    return solve_intrinsics([v[0] for v in views], [v[1] for v in views], SIZE, "k1k2")


def renders(n_sessions: int) -> None:
    cam = PinholeCamera.seed_reference(SIZE)
    truth = {
        "fx": cam.K[0, 0],
        "fy": cam.K[1, 1],
        "cx": cam.K[0, 2],
        "cy": cam.K[1, 2],
        "k1": cam.dist[0],
        "k2": cam.dist[1],
    }
    obj_all = BOARD.object_points()
    z_before: dict[str, list[float]] = {k: [] for k in truth}
    z_after: dict[str, list[float]] = {k: [] for k in truth}
    factors, fired = [], 0
    for s in range(n_sessions):
        rng = np.random.default_rng(100 + s)
        views = []
        for T in scenario_poses("good", cam, BOARD, 20, rng):
            det, _ = detect_board(render_view(cam, BOARD, T, rng, Photometry.random(rng)), BOARD)
            if det is not None:
                views.append((obj_all[det.corner_ids], det.corners_px))
        sol = _solve(views)
        cov = sol.covariance
        assert cov is not None and cov.view_factor is not None
        factors.append(cov.view_factor)
        fired += cov.inflated
        scale = cov.view_factor if cov.inflated else 1.0
        for k, v in _values(sol).items():
            z_after[k].append((v - truth[k]) / sol.sigma[k])
            z_before[k].append((v - truth[k]) / (sol.sigma[k] / scale))
    print(
        f"renders ({n_sessions} sessions): sigma_factor median {np.median(factors):.2f}, max "
        f"{max(factors):.2f}; "
        f"rule fired (> {MAX_SIGMA_FACTOR}) in {fired}"
    )
    for k in truth:
        print(
            f"  {k}: z mean {np.mean(z_after[k]):+.2f}, z sd before {np.std(z_before[k], ddof=1):.2f}, "
            f"after {np.std(z_after[k], ddof=1):.2f}"
        )


def real_left() -> None:
    views = detected(sorted(LEFT_RIGHT.glob("left*.jpg")), BOARD)
    sol = _solve(views)
    cov = sol.covariance
    assert cov is not None and cov.view_factor is not None and cov.covariance is not None
    jacobian = np.sqrt(np.diag(cov.covariance)) / (cov.view_factor if cov.inflated else 1.0)
    est = np.array(
        [[_values(_solve(views[:i] + views[i + 1 :]))[n] for n in cov.names] for i in range(len(views))]
    )
    n = len(views)
    jackknife = np.sqrt((n - 1) / n * np.sum((est - est.mean(0)) ** 2, axis=0))
    ratios = ", ".join(f"{name} {r:.2f}" for name, r in zip(cov.names, jackknife / jacobian, strict=True))
    print(
        f"opencv-left-right left ({n} views): sigma_factor {cov.view_factor:.2f}, fired {cov.inflated}; "
        f"jackknife / Jacobian sigma: {ratios}"
    )
    rng = np.random.default_rng(0)
    halves = []
    for _ in range(40):
        idx = rng.permutation(n)
        for h in (idx[:7], idx[7:]):
            c = _solve([views[i] for i in h]).covariance
            assert c is not None and c.view_factor is not None
            halves.append(c.view_factor)
    print(
        f"  40 random 7 + 6 splits: sigma_factor median {np.median(halves):.2f}, min {min(halves):.2f}; "
        f"fired in {sum(f > MAX_SIGMA_FACTOR for f in halves)} / {len(halves)} halves"
    )


if __name__ == "__main__":
    renders(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
    real_left()
