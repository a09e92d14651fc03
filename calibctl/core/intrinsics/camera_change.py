"""Did the camera change during the session? A split of the views in capture order.

A lens that is knocked or refocused half way through a capture (focal length 0.5-1.5 % off, the principal
point a few pixels away) is still one camera to every other test: the two-camera split (core.capture.
camera_split) scores prediction errors, and a 1 % focal change is largely absorbed by each view's re-fitted
board distance (ratio 1.35 under its 1.4 limit); the solve blends the two cameras into one, accepted, several
sigma from both. What the views keep is the order they were taken in: before the change they pull the
intrinsics one way, after it the other.

The test, in two steps:
  1. Scan (``scan_change``, no re-solve): from the full solve's per-view reduced information S_i and
     scores g_i (core.intrinsics.covariance, poses eliminated), the score test of a step in (fx, fy, cx,
     cy) from view k on, distortion held common: LM_k = G_b' E_k^-1 G_b / s^2, G_b the summed scores of
     views k..V-1 restricted to those parameters, E_k = S_b[P,P] - S_b[P,:] S^-1 S_b[:,P] its efficient
     information; E_k^-1 G_b is the one-step estimate of the step. The k with the largest LM_k, each side
     holding at least ``min_segment`` views, is the candidate.
  2. Judge (``judge_change``): the two sides are solved apart and their (fx, fy, cx, cy) compared under
     each side's own covariance, widened by its view-level factor when above 1 (the per-view error a real
     session carries must not read as a change): chi2 = d' (C_a + C_b)^-1 d. The camera changed when chi2
     exceeds ``CHANGE_CHI2`` and the step is at least ``MIN_FOCAL_STEP`` or ``MIN_CENTRE_STEP_PX`` (a step
     too small to matter is not worth a re-capture).

Measured (benchmarks/bench_camera_change.py, benchmarks/results/verdicts.md; renders through the real
detector, 20 views, the step at view 10, k1k2): chi2 on 60 clean sessions median 4.9, max 11.9 (0 called
changed); focal +0.5 % min 67.6, +1 % min 204.5, +1.5 % min 554.7, principal point +3 px min 19.1 (10 / 10
each called changed); real sets (opencv-left-right left / right, udacity-camcal, baka-stereo left / right)
at most 16.2, none called changed. A 3 px principal-point step is the weakest catch: its margin over the
limit is small.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # lint reads changed_hint without OpenCV (a lint FILE starts without cv2)
    from calibctl.core.intrinsics.covariance import IntrinsicCovariance
    from calibctl.core.intrinsics.solve import IntrinsicsSolution
from calibctl.errors import NumericalError

STEP_PARAMETERS = ("fx", "fy", "cx", "cy")
MIN_SEGMENT_VIEWS = 5


@dataclass(frozen=True)
class ChangeScan:
    """The most likely change point of a session in capture order.

    Attributes:
        split: index of the first view after the change (0 < split < V).
        statistic: LM_split, the score statistic there (chi-square with len(names) dof for one fixed split).
        names: the parameters the step is in (``STEP_PARAMETERS`` the model has free).
        step: (len(names),) one-step estimate of second - first, px.
    """

    split: int
    statistic: float
    names: tuple[str, ...]
    step: np.ndarray


def scan_change(cov: IntrinsicCovariance, min_segment: int = MIN_SEGMENT_VIEWS) -> ChangeScan | None:
    """The score scan of step 1 (module docstring) from a solve's covariance, views in capture order; None
    when the covariance has no per-view blocks, fewer than 2 x ``min_segment`` views, or no step parameter."""
    if cov.view_information is None or cov.view_influences is None or not cov.residual_variance_px2 > 0:
        return None
    blocks, influences = cov.view_information, cov.view_influences
    n = len(blocks)
    P = [i for i, name in enumerate(cov.names) if name in STEP_PARAMETERS]
    if n < 2 * min_segment or not P:
        return None
    S = blocks.sum(axis=0)
    scores = influences @ S  # g_i = S @ (S^-1 g_i); S symmetric
    d = np.sqrt(np.diag(S))
    S_unit_inv = np.linalg.inv(S / np.outer(d, d))
    after_S = np.cumsum(blocks[::-1], axis=0)[::-1]  # after_S[k] = sum_{i >= k} S_i
    after_g = np.cumsum(scores[::-1], axis=0)[::-1]
    best: ChangeScan | None = None
    for k in range(min_segment, n - min_segment + 1):
        Sb, Gb = after_S[k], after_g[k][P]
        cross = Sb[P, :] / d  # S_b[P,:] S^-1 S_b[:,P] through the unit-diagonal inverse
        E = Sb[np.ix_(P, P)] - cross @ S_unit_inv @ cross.T
        try:
            step = np.linalg.solve(E, Gb)
        except np.linalg.LinAlgError:
            continue
        lm = float(Gb @ step) / cov.residual_variance_px2
        if np.isfinite(lm) and (best is None or lm > best.statistic):
            best = ChangeScan(k, lm, tuple(cov.names[i] for i in P), step)
    return best


@dataclass(frozen=True)
class ChangeVerdict:
    """Step 2: the two sides of the split solved apart and compared.

    Attributes:
        split: first view after the change. chi2: d' (C_a + C_b)^-1 d over ``names`` (the free ones of
            STEP_PARAMETERS). parts: that chi2 of the focal length alone and of the principal point alone.
        before, after: each side's (fx, fy, cx, cy) as solved (STEP_PARAMETERS order), px.
        focal_step: (f_after - f_before) / f_before, the mean of fx and fy's. centre_step_px: |(dcx, dcy)|.
        changed: chi2 > the limit and a step at least the smallest that matters.
    """

    split: int
    chi2: float
    names: tuple[str, ...]
    before: np.ndarray
    after: np.ndarray
    focal_step: float
    centre_step_px: float
    changed: bool
    parts: dict[str, float]
    limit: float


def _side_covariance(sol: IntrinsicsSolution, P: Sequence[int]) -> np.ndarray | None:
    cov = sol.covariance
    if cov is None or cov.covariance is None:
        return None
    jac = cov.jacobian_covariance
    assert jac is not None
    factor = max(1.0, cov.view_factor or 1.0)
    return jac[np.ix_(P, P)] * factor**2


CHANGE_CHI2 = 18.0
MIN_FOCAL_STEP = 0.003
MIN_CENTRE_STEP_PX = 1.5


def judge_change(
    solution: IntrinsicsSolution,
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    min_segment: int = MIN_SEGMENT_VIEWS,
    limit: float = CHANGE_CHI2,
) -> ChangeVerdict | None:
    """Steps 1 and 2 (module docstring) on a solve of these views (capture order); None when the session is
    too short to split or a side cannot be solved with a covariance."""
    from calibctl.core.intrinsics.solve import solve_intrinsics, starts_warm

    if solution.covariance is None:
        return None
    scan = scan_change(solution.covariance, min_segment)
    if scan is None:
        return None
    obj, img = list(object_points_per_view), list(image_points_per_view)
    k = scan.split
    # each side starts from the whole session's solve where that finds the same minimum (solve.starts_warm)
    warm = starts_warm(solution.model)
    sides = []
    for part in (slice(0, k), slice(k, None)):
        try:
            sides.append(
                solve_intrinsics(
                    obj[part],
                    img[part],
                    image_size,
                    solution.model,
                    initial=solution.camera_matrix if warm else None,
                    initial_dist=solution.dist_coeffs if warm else None,
                )
            )
        except NumericalError:
            return None
    names = solution.covariance.names
    P = [names.index(n) for n in scan.names]
    covs = [_side_covariance(s, P) for s in sides]
    if covs[0] is None or covs[1] is None:
        return None
    values = [np.array([_value(s, n) for n in scan.names]) for s in sides]
    d = values[1] - values[0]
    try:
        chi2 = float(d @ np.linalg.solve(covs[0] + covs[1], d))
    except np.linalg.LinAlgError:
        return None
    focal = [i for i, n in enumerate(scan.names) if n in ("fx", "fy")]
    centre = [i for i, n in enumerate(scan.names) if n in ("cx", "cy")]
    C = covs[0] + covs[1]
    sub = {
        what: float(d[idx] @ np.linalg.solve(C[np.ix_(idx, idx)], d[idx])) if idx else 0.0
        for what, idx in (("focal", focal), ("centre", centre))
    }
    focal_step = float(np.mean(d[focal] / values[0][focal])) if focal else 0.0
    centre_step = float(np.linalg.norm(d[centre])) if centre else 0.0
    big = abs(focal_step) >= MIN_FOCAL_STEP or centre_step >= MIN_CENTRE_STEP_PX
    before, after = ([_value(side, n) for n in STEP_PARAMETERS] for side in sides)
    changed = bool(chi2 > limit and big)
    return ChangeVerdict(
        k, chi2, scan.names, np.array(before), np.array(after), focal_step, centre_step, changed, sub, limit
    )


def _value(sol: IntrinsicsSolution, name: str) -> float:
    K = sol.camera_matrix
    return float({"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}[name])


def changed_hint(focal_step: float, centre_step_px: float) -> str:
    """The operator's hint for a camera that changed during the session (lint's camera-changed, the capture
    gate that names it as the cause)."""
    return (
        f"the camera changed during the session (focal moved by {100 * focal_step:+.2f} %, principal point "
        f"by {centre_step_px:.1f} px): check the lens lock and focus, then capture again"
    )
