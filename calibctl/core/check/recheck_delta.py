"""The delta-model test of ``calibctl check``: do the fresh views pull focal, cx or cy off the stored values?

A focal change scales the image about the principal point, a principal-point shift translates it; on
tilted views a rigid board pose cannot absorb either completely. One weighted Gauss-Newton step of
(focal scale, cx, cy, k1, k2) from the fresh residuals, with each view's six pose parameters projected
out (Schur complement), measures what the pose could not absorb. The step is a score test of "the stored
model is right": it is measured, never applied, so there is no loop to share with the solver of the
fits (calibctl.core.lm): no damping (it would bias the measured step towards zero) and no acceptance.

Weights: each view's residuals are divided by that view's own noise (its mean square over its 2N - 6
degrees of freedom), so a blurred or steep view with 2x the detector noise counts a quarter as much
instead of dominating the estimate and its error bar. Under "unchanged" the step's covariance is then the
inverse of the weighted normal matrix; the stored calibration's own covariance of (focal, cx, cy) is
added, since the stored values carry their error too.

The Jacobian is taken by central differences through ``solve.project_points``, so the same test works
for every stored model, pinhole or fisheye (whose k1, k2 are its first two Kannala-Brandt terms).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.solve import project_points

SHIFT_NAMES = ("focal", "cx", "cy")  # tested; k1 and k2 are estimated alongside as nuisance parameters
POSE_PARAMETERS = 6
_STEP_POSE = 1e-6  # rad and m: central-difference steps
_STEP_INTRINSIC = (1e-6, 1e-3, 1e-3, 1e-6, 1e-6)  # focal scale, cx px, cy px, k1, k2


@dataclass(frozen=True)
class ParameterShift:
    """How far the fresh views pull one intrinsic from its stored value (one linearised step, never applied).

    ``shift`` is in px (cx, cy) or relative (focal: 0.005 = +0.5 %); ``sigma`` combines the fresh
    estimate's one-sigma with the stored one; the test is two-sided |shift| / sigma <= z_limit.
    """

    name: str
    shift: float
    sigma: float
    z_limit: float

    @property
    def z(self) -> float:
        return self.shift / self.sigma

    @property
    def passed(self) -> bool:
        return abs(self.z) <= self.z_limit


def _perturbed(
    camera_matrix: np.ndarray, dist_coeffs: np.ndarray, k: int, h: float
) -> tuple[np.ndarray, np.ndarray]:
    K = camera_matrix.copy()
    D = dist_coeffs.copy()
    if k == 0:
        K[0, 0] *= 1.0 + h
        K[1, 1] *= 1.0 + h
    elif k in (1, 2):
        K[k - 1, 2] += h
    else:
        D[k - 3] += h
    return K, D


def view_jacobians(
    object_points: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str,
) -> tuple[np.ndarray, np.ndarray]:
    """(2N, 6) d(projection)/d(rvec, tvec) and (2N, 5) d/d(focal scale, cx, cy, k1, k2), rows u0, v0, u1, ...

    Args:
        object_points: (N, 3) board frame, metres. rvec, tvec: (3,) T_cam_board. dist_coeffs: (n >= 2,).
    """
    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    K = np.asarray(camera_matrix, np.float64)
    D = np.asarray(dist_coeffs, np.float64).ravel()
    pose = np.concatenate([np.asarray(rvec, np.float64).ravel(), np.asarray(tvec, np.float64).ravel()])
    J_pose = np.empty((2 * len(obj), POSE_PARAMETERS))
    for k in range(POSE_PARAMETERS):
        step = np.zeros(6)
        step[k] = _STEP_POSE
        plus = project_points(obj, (pose + step)[:3], (pose + step)[3:], K, D, model)
        minus = project_points(obj, (pose - step)[:3], (pose - step)[3:], K, D, model)
        J_pose[:, k] = ((plus - minus) / (2 * _STEP_POSE)).ravel()
    J_int = np.empty((2 * len(obj), len(_STEP_INTRINSIC)))
    for k, h in enumerate(_STEP_INTRINSIC):
        plus = project_points(obj, pose[:3], pose[3:], *_perturbed(K, D, k, h), model)
        minus = project_points(obj, pose[:3], pose[3:], *_perturbed(K, D, k, -h), model)
        J_int[:, k] = ((plus - minus) / (2 * h)).ravel()
    return J_pose, J_int


def intrinsic_shifts(
    object_points_per_view: Sequence[np.ndarray],
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    rvecs: Sequence[np.ndarray],
    tvecs: Sequence[np.ndarray],
    residuals_px: Sequence[np.ndarray],
    stored_covariance: np.ndarray,
    alpha: float,
    model: str = DEFAULT_MODEL,
) -> tuple[ParameterShift, ...]:
    """The delta step and its test (see module docstring). Empty when the views do not constrain it.

    Args:
        object_points_per_view: V arrays (N_i, 3), metres. rvecs, tvecs: V (3,) fitted T_cam_board.
        residuals_px: V arrays (N_i, 2) observed - projected under the stored model.
        stored_covariance: (3, 3) covariance of the stored (focal scale, cx px, cy px).
        alpha: false-fail level shared (Bonferroni) by the three two-sided tests.
    """
    K = np.asarray(camera_matrix, np.float64)
    D = np.asarray(dist_coeffs, np.float64).ravel()
    if D.size < 2:
        D = np.concatenate([D, np.zeros(2 - D.size)])
    n_par = len(_STEP_INTRINSIC)
    A = np.zeros((n_par, n_par))
    b = np.zeros(n_par)
    for obj, rvec, tvec, res in zip(object_points_per_view, rvecs, tvecs, residuals_px, strict=True):
        r = np.asarray(res, np.float64).reshape(-1)  # u0, v0, u1, v1, ... as the Jacobian's rows
        dof = r.size - POSE_PARAMETERS
        if dof < 2:
            continue
        J_pose, J_int = view_jacobians(obj, rvec, tvec, K, D, model)
        weight = dof / max(float(r @ r), 1e-12)  # 1 / this view's noise variance per coordinate
        J_perp = J_int - J_pose @ np.linalg.lstsq(J_pose, J_int, rcond=None)[0]
        r_perp = r - J_pose @ np.linalg.lstsq(J_pose, r, rcond=None)[0]
        A += weight * (J_perp.T @ J_perp)
        b += weight * (J_perp.T @ r_perp)
    try:
        if np.linalg.cond(A) > 1e14:
            return ()
        cov = np.linalg.inv(A)[:3, :3] + np.asarray(stored_covariance, np.float64)
        step = np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return ()  # the fresh views do not constrain the intrinsics at all (e.g. one square-on view)
    z_limit = NormalDist().inv_cdf(1.0 - alpha / (2 * len(SHIFT_NAMES)))
    return tuple(
        ParameterShift(name, float(step[i]), math.sqrt(max(float(cov[i, i]), 1e-30)), z_limit)
        for i, name in enumerate(SHIFT_NAMES)
    )


def stored_delta_covariance(sigma: dict[str, float]) -> np.ndarray:
    """(3, 3) diagonal covariance of (focal scale, cx, cy) from one-sigmas (``focal`` relative; absent =
    0)."""
    return np.diag([sigma.get(name, 0.0) ** 2 for name in SHIFT_NAMES])
