"""What the decisive capture gate blames (core/capture/projection_gate.py ``cause_first``), on real sets and
on renders with known truth.

``real``: for each real set (the corners calibctl detects, views in file-name order) and lens model (k1k2, as
a default ``calibrate`` asks; none, as a plain ``capture`` chooses between k1k2 and fisheye): the view-level
factor, the gate's worst one-sigma over the image with the Jacobian covariance (what the gate judged before)
and with the covariance calibctl reports (what it judges now), the worst one-sigma where the board was seen,
the verdict at 5 px, and the reason and first words of the hint once ``cause_first`` has looked for a
lens-model misfit, a bowed board, a camera that changed during the session and a board that moved.

``explain``: what brings each real set's factor down: richer lens models (k1k2p1p2k3, rational, fisheye)
and a board allowed to bow (core/intrinsics/board_warp.py).

``caliscope`` (with ``real`` or ``explain``): the four webcams of caliscope-4cam too (every video frame
calibctl's detector finds the board in; about 10 s more).

``baka``: baka-stereo's per-view RMS, left against right (a board that moves is seen by both cameras), and
its two capture sessions (file stems 3.6 h apart: views 1-19 and 20-30) solved apart.

``renders N``: N clean sessions rendered through the real detector (tests/workflows/sessions.py
``rendered_session``, seeds 100 + i, as benchmarks/bench_camera_change.py) and 10 each with a focal step
(+0.5 / +1 / +1.5 %) or a 3 px principal-point step at view 10: how many the gate refuses at 5 px judging
the Jacobian covariance (before) and the reported one (now), and the causes it names.

Run: python benchmarks/bench_gate_cause.py [real] [explain] [baka] [caliscope] [renders N]   (from the
repository root; the real sets need ../shared/datasets; no argument: real, explain and baka)
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent.parent))
from bench_diff import detected  # noqa: E402  (benchmarks/ scripts import each other)

from calibctl.core.board.board_spec import BoardSpec  # noqa: E402
from calibctl.core.capture.detect import detect_board  # noqa: E402
from calibctl.core.capture.projection_gate import (  # noqa: E402
    PROJECTION_SIGMA_MAX_PX,
    Region,
    cause_first,
    projection_gate,
    solve_for_gate,
    worst_where_seen,
)
from calibctl.core.intrinsics.board_warp import fit_board_warp  # noqa: E402
from calibctl.core.intrinsics.report_maps import projection_uncertainty, unproject  # noqa: E402
from calibctl.core.intrinsics.solve import IntrinsicsSolution, solve_intrinsics  # noqa: E402
from calibctl.errors import NumericalError  # noqa: E402
from tests.core.intrinsics.test_solve_real import _natural  # noqa: E402
from tests.datasets import BAKA_STEREO, DATASETS, LEFT_RIGHT, UDACITY  # noqa: E402

B9 = BoardSpec.chessboard(9, 6, 0.025)
BAKA = BoardSpec.chessboard(7, 10, 0.023)
ACFR = BoardSpec.chessboard(5, 7, 0.095)
SETS = [
    (
        "acfr-lidar-camera",
        sorted((DATASETS / "acfr-lidar-camera" / "images").glob("*.png"), key=_natural),
        ACFR,
    ),
    ("baka-stereo left", sorted((BAKA_STEREO / "left").glob("*.jpg"), key=_natural), BAKA),
    ("baka-stereo right", sorted((BAKA_STEREO / "right").glob("*.jpg"), key=_natural), BAKA),
    ("udacity-camcal", sorted(UDACITY.glob("calibration*.jpg"), key=_natural), B9),
    ("opencv-left-right left", sorted(LEFT_RIGHT.glob("left*.jpg")), B9),
    ("opencv-left-right right", sorted(LEFT_RIGHT.glob("right*.jpg")), B9),
]
IMAGE = Region("image")
LIMIT = PROJECTION_SIGMA_MAX_PX


def jacobian_worst(sol: IntrinsicsSolution, size: tuple[int, int]) -> float:
    """The gate's worst sigma over the image with the Jacobian covariance alone (what it judged before)."""
    cov = sol.covariance
    assert cov is not None and cov.jacobian_covariance is not None
    grid = (max(16, round(size[0] / 20)), max(12, round(size[1] / 20)))
    umap = projection_uncertainty(
        sol.camera_matrix,
        sol.dist_coeffs,
        cov.jacobian_covariance,
        cov.names,
        sol.aspect_ratio,
        size,
        grid,
        fisheye=sol.model == "fisheye",
        rotation_fit=np.ones((grid[1], grid[0]), bool),
    )
    return float(np.nanmax(umap.sigma_px))


def _factor(sol: IntrinsicsSolution) -> float:
    return (
        float(sol.covariance.view_factor) if sol.covariance and sol.covariance.view_factor else float("nan")
    )


def _sets():
    for name, paths, board in SETS:
        views = detected(paths, board)
        size = tuple(cv2.imread(str(paths[0])).shape[1::-1])
        yield name, size, [a for a, _ in views], [b for _, b in views]
    if "caliscope" in sys.argv:
        yield from _caliscope()


def _caliscope():
    """caliscope-4cam's four webcams: every video frame calibctl's detector finds the inverted ChArUco in
    (benchmarks/bench_rig_caliscope.py reads them the same way)."""
    board = BoardSpec.charuco(4, 5, 0.054, 0.054 * 0.75, "DICT_4X4_1000", inverted=True)
    for cam in range(4):
        capture = cv2.VideoCapture(str(DATASETS / "caliscope-4cam" / "extrinsic" / f"cam_{cam}.mp4"))
        obj, img = [], []
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            found, _ = detect_board(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), board)
            if found is not None:
                obj.append(board.object_points()[found.corner_ids])
                img.append(found.corners_px)
        capture.release()
        yield f"caliscope-4cam cam_{cam}", (1280, 720), obj, img


def real() -> None:
    print(
        "| set | views | model | factor | worst sigma, Jacobian (before) | reported (judged) | where seen "
        "| verdict at 5 px | reason | hint |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, size, obj, img in _sets():
        for model in ("k1k2", None):
            try:
                sol: IntrinsicsSolution | NumericalError = solve_for_gate(obj, img, size, model)
            except NumericalError as exc:
                sol = exc
            gate = projection_gate(sol, size, IMAGE, LIMIT)
            named = cause_first(gate, sol, obj, img, size, IMAGE, LIMIT)
            if isinstance(sol, NumericalError):
                print(f"| {name} | {len(obj)} | {model or 'none'} (-) | | | | | FAIL | {named.reason} | |")
                continue
            assert sol.covariance is not None
            seen = worst_where_seen(sol, sol.covariance, img, size, IMAGE)
            hint = " ".join((named.hint or "").split()[:12])
            print(
                f"| {name} | {len(obj)} | {model or 'none'} ({sol.model}) | {_factor(sol):.2f} | "
                f"{jacobian_worst(sol, size):.2f} | {gate.value:.2f} | {seen:.2f} | "
                f"{'pass' if gate.passed else 'FAIL'} | {named.reason or '-'} | {hint} |"
            )


def explain() -> None:
    models = ("k1k2", "k1k2p1p2k3", "rational", "fisheye")
    print(
        "| set | "
        + " | ".join(f"{m}: rms / factor / reported" for m in models)
        + " | k1k2, board bowed: bow x, y mm / rms / factor / reported | flat vs bowed, max px |"
    )
    print("|---|" + "---|" * (len(models) + 2))
    for name, size, obj, img in _sets():
        cells = []
        for m in models:
            try:
                sol = solve_intrinsics(obj, img, size, m)
            except NumericalError:
                cells.append("not solvable")
                continue
            gate = projection_gate(sol, size, IMAGE, LIMIT)
            cells.append(f"{sol.rms_px:.3f} / {_factor(sol):.2f} / {gate.value:.3g}")
        flat = solve_intrinsics(obj, img, size, "k1k2")
        warp = fit_board_warp(flat, obj, img)
        if warp is None:
            cells += ["not solvable", "-"]
        else:
            bowed = projection_gate(warp.bowed, size, IMAGE, LIMIT)
            cells.append(
                f"{1e3 * warp.warp_m[0]:+.2f}, {1e3 * warp.warp_m[1]:+.2f} / {warp.bowed.rms_px:.3f} / "
                f"{_factor(warp.bowed):.2f} / {bowed.value:.3g}"
            )
            cells.append(f"{flat_against_bowed_px(flat, warp.bowed, size):.2f}")
        print(f"| {name} | " + " | ".join(cells) + " |")


def flat_against_bowed_px(
    flat: IntrinsicsSolution, bowed: IntrinsicsSolution, size: tuple[int, int]
) -> float:
    """The largest rotation-compensated difference over the image between the flat-board calibration and
    the bowed-board one (bench_verdicts.py's measure of one calibration against another)."""
    from bench_verdicts import _compensated_max, _grid  # noqa: PLC0415

    q = _grid(size, IMAGE)
    xy = unproject(q, bowed.camera_matrix, bowed.dist_coeffs)
    return _compensated_max(flat, np.concatenate([xy, np.ones((len(xy), 1))], axis=1), q)


def baka() -> None:
    """Whose error is baka-stereo's: the per-view RMS of the two cameras at the same instants (a board that
    moves is seen by both), and the two capture sessions in its file stems solved apart."""
    sets = {name: (size, obj, img) for name, size, obj, img in _sets() if name.startswith("baka")}
    rms = {}
    for name, (size, obj, img) in sets.items():
        sol = solve_intrinsics(obj, img, size, "k1k2", uncertainty=False)
        rms[name] = sol.per_view_rms_px
        parts = []
        for label, part in (("views 1-19", slice(0, 19)), ("views 20-30", slice(19, 30))):
            half = solve_intrinsics(obj[part], img[part], size, "k1k2", uncertainty=False)
            parts.append(f"{label}: rms {half.rms_px:.3f} px, fx {half.fx:.1f}")
        print(f"{name}: per-view rms {rms[name].min():.2f}-{rms[name].max():.2f} px; " + "; ".join(parts))
    left, right = rms["baka-stereo left"], rms["baka-stereo right"]
    ranks = [np.argsort(np.argsort(x)) for x in (left, right)]
    print(
        f"per-view rms, left against right: Spearman {np.corrcoef(*ranks)[0, 1]:.2f} over {len(left)} pairs"
    )


def renders(n_clean: int, n_step: int = 10) -> None:
    from tests.workflows.sessions import CHANGE_SIZE, rendered_session  # noqa: PLC0415

    cases = [("clean", [rendered_session(100 + i) for i in range(n_clean)])]
    for focal in (0.005, 0.01, 0.015):
        cases.append((f"focal +{100 * focal:g} %", [rendered_session(200 + i, focal) for i in range(n_step)]))
    steps = [(3.0, 0.0) if i % 2 == 0 else (0.0, 3.0) for i in range(n_step)]
    cases.append(("centre +3 px", [rendered_session(300 + i, 0.0, steps[i]) for i in range(n_step)]))
    print(
        "| case | sessions | factor median / max | inflated (> 1.5) | refused, Jacobian (before) "
        "| refused, reported (now) | causes named (now) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, sessions in cases:
        factors, inflated, before, now, causes = [], 0, 0, 0, Counter()
        for obj, img in sessions:
            sol = solve_for_gate(obj, img, CHANGE_SIZE, "k1k2")
            assert sol.covariance is not None
            factors.append(_factor(sol))
            inflated += int(sol.covariance.inflated)
            before += int(jacobian_worst(sol, CHANGE_SIZE) > LIMIT)
            gate = projection_gate(sol, CHANGE_SIZE, IMAGE, LIMIT)
            if not gate.passed:
                now += 1
                causes[cause_first(gate, sol, obj, img, CHANGE_SIZE, IMAGE, LIMIT).reason] += 1
        named = ", ".join(f"{k} {v}" for k, v in sorted(causes.items())) or "-"
        print(
            f"| {name} | {len(sessions)} | {np.median(factors):.2f} / {max(factors):.2f} | {inflated} | "
            f"{before} | {now} | {named} |",
            flush=True,
        )


if __name__ == "__main__":
    args = sys.argv[1:] or ["real", "explain", "baka"]
    if "real" in args:
        real()
    if "explain" in args:
        explain()
    if "baka" in args:
        baka()
    if "renders" in args:
        k = args.index("renders")
        renders(int(args[k + 1]) if len(args) > k + 1 else 60)
