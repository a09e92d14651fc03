"""Joint non-linear refinement of X = T_a_b and its covariance from the residual scatter.

Two residual models, chosen by what the data are:

- relative motions (``--input motions``): per motion, log(R_A R_X R_B^T R_X^T) and
  (R_A - I) t_X - R_X t_B + t_A. Honest when the motions' errors are independent.
- poses (each sensor's pose in its own fixed world; the robot arm): A X = X B becomes
  T_wa_a,i X = Y T_wb_b,i with Y = T_wa_wb unknown too (12 parameters), and the residual is the
  per-pose misfit inv(Y T_wb_b,i) T_wa_a,i X. Consecutive motions share a pose, so their errors
  are correlated; per-pose residuals are not, which is what keeps this covariance honest, and every
  pose is compared with every other through Y (as all-pairs methods do), not only its neighbours.

Gauss-Newton with a central-difference Jacobian; rotation and translation residuals are each
weighted by 1 / their RMS (re-estimated every iteration, dof 3m - p per group), so the covariance
(J^T J)^-1 is in the data's own units. Rotations are left perturbations exp(d) R, d in radians.

Why this loop is not calibctl.core.lm (the shared solver of the fisheye, rig and board-pose problems):
re-weighting every iteration makes the cost a moving target (the weighted sum of squares at one
iterate is not comparable with the next one's), so LM's accept-a-step-that-lowers-the-cost rule has
nothing fixed to judge by (the loop stops on the step size instead: CONVERGED_STEP); and the step is
``lstsq`` on J (SVD, minimum-norm), which works at the condition number of J rather than of J^T J (the
normal equations the shared solver takes) in a problem that mixes radians and metres, and stays finite
where the motions leave a direction of X unconstrained (a planar robot) for the singular-information
check below to name.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibctl.core.blas_threads import single_threaded
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.handeye import (
    METHODS,
    Motions,
    motion_residuals,
    solve_rotation_park,
    solve_rotation_tsai,
    solve_translation,
)

RESIDUAL_FLOOR = 1e-12  # exact (noise-free) data: weights stay finite and the covariance is ~0
JACOBIAN_STEP = 1e-6  # central differences in rad / m
SINGULAR_RCOND = 1e-10  # J^T J eigenvalues below this * largest: a direction the data does not see
MAX_ITERATIONS = 20
CONVERGED_STEP = 1e-9  # rad / m: a nanometre; smaller steps only chase rounding

Residuals = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # params -> (m, 3) rad, (m, 3) m


@dataclass(frozen=True)
class HandEyeFit:
    """The refined X = T_a_b with its uncertainty and per-motion residuals.

    residual_*: (n, 3) per-motion misfit of A X = X B at the result (what outliers are judged on).
    covariance: (6, 6) over (rotation perturbation in frame a, rad; translation, m), or None with
    ``refused_reason`` when the data leave a direction unconstrained or have no redundancy.
    """

    T_a_b: np.ndarray
    method: str
    model: str  # "motions" or "poses": the refinement's residual model
    residual_rotation_rad: np.ndarray
    residual_translation_m: np.ndarray
    sigma_residual_rotation_rad: float
    sigma_residual_translation_m: float
    covariance: np.ndarray | None
    refused_reason: str | None
    iterations: int

    @property
    def sigma_rotation_deg(self) -> np.ndarray | None:
        """(3,) one-sigma of the rotation about frame a's x, y, z axes, degrees."""
        return None if self.covariance is None else np.degrees(np.sqrt(np.diag(self.covariance)[:3]))

    @property
    def sigma_translation_m(self) -> np.ndarray | None:
        return None if self.covariance is None else np.sqrt(np.diag(self.covariance)[3:])


@dataclass(frozen=True)
class _Solution:
    params: np.ndarray
    sigma_rot: float
    sigma_t: float
    covariance: np.ndarray | None  # over all parameters
    singular: bool
    iterations: int


def _group_sigma(residual: np.ndarray, dof: int) -> float:
    return max(float(np.sqrt(np.sum(residual**2) / max(dof, 1))), RESIDUAL_FLOOR)


def _weighted(residuals: Residuals, params: np.ndarray, w_rot: float, w_t: float) -> np.ndarray:
    rot, trans = residuals(params)
    return np.concatenate([(rot * w_rot).ravel(), (trans * w_t).ravel()])


def _jacobian(residuals: Residuals, params: np.ndarray, w_rot: float, w_t: float) -> np.ndarray:
    cols = []
    for k in range(params.size):
        step = np.zeros(params.size)
        step[k] = JACOBIAN_STEP
        cols.append(
            (
                _weighted(residuals, params + step, w_rot, w_t)
                - _weighted(residuals, params - step, w_rot, w_t)
            )
            / (2 * JACOBIAN_STEP)
        )
    return np.column_stack(cols)


def _gauss_newton(residuals: Residuals, params0: np.ndarray, dof: int) -> _Solution:
    params = np.asarray(params0, np.float64).copy()
    it = 0
    for it in range(1, MAX_ITERATIONS + 1):  # noqa: B007 - the count is reported
        rot, trans = residuals(params)
        w_rot, w_t = 1.0 / _group_sigma(rot, dof), 1.0 / _group_sigma(trans, dof)
        step = np.linalg.lstsq(
            _jacobian(residuals, params, w_rot, w_t), -_weighted(residuals, params, w_rot, w_t), rcond=None
        )[0]
        params = params + step
        if np.max(np.abs(step)) < CONVERGED_STEP:
            break
    rot, trans = residuals(params)
    s_rot, s_t = _group_sigma(rot, dof), _group_sigma(trans, dof)
    J = _jacobian(residuals, params, 1.0 / s_rot, 1.0 / s_t)
    information = J.T @ J
    eig = np.linalg.eigvalsh(information)
    singular = bool(eig[0] <= SINGULAR_RCOND * eig[-1])
    return _Solution(params, s_rot, s_t, None if singular else np.linalg.inv(information), singular, it)


def _x_of(params: np.ndarray, R_X0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return se3.rotation_from_rotvec(params[:3]) @ R_X0, params[3:6]


def refine_motions(motions: Motions, R_X0: np.ndarray, t_X0_m: np.ndarray) -> _Solution:
    def residuals(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return motion_residuals(motions, *_x_of(params, R_X0))

    return _gauss_newton(residuals, np.concatenate([np.zeros(3), t_X0_m]), 3 * motions.n - 3)


def _initial_y(T_wa_a: np.ndarray, T_wb_b: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Y = T_wa_wb averaged over the poses: chordal mean of the rotations, mean of the translations."""
    Ys = np.array([T_a @ X @ se3.invert(T_b) for T_a, T_b in zip(T_wa_a, T_wb_b, strict=True)])
    U, _, Vt = np.linalg.svd(Ys[:, :3, :3].sum(axis=0))
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0]) @ Vt
    return se3.transform(R, Ys[:, :3, 3].mean(axis=0))


def refine_poses(T_wa_a: np.ndarray, T_wb_b: np.ndarray, R_X0: np.ndarray, t_X0_m: np.ndarray) -> _Solution:
    """AX = YB on (n, 4, 4) poses; parameters (dX, t_X, dY, t_Y)."""
    Y0 = _initial_y(T_wa_a, T_wb_b, se3.transform(R_X0, t_X0_m))
    R_a, t_a, R_b, t_b = T_wa_a[:, :3, :3], T_wa_a[:, :3, 3], T_wb_b[:, :3, :3], T_wb_b[:, :3, 3]

    def residuals(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R_X, t_X = _x_of(params, R_X0)
        R_Y, t_Y = se3.rotation_from_rotvec(params[6:9]) @ Y0[:3, :3], params[9:12]
        R_M, t_M = R_Y @ R_b, t_b @ R_Y.T + t_Y  # Y T_wb_b: b's pose in wa, via b's log
        R_N, t_N = R_a @ R_X, R_a @ t_X + t_a  # T_wa_a X: b's pose in wa, via a's log
        R_Mt = R_M.transpose(0, 2, 1)
        return se3.rotvecs_from_rotations(R_Mt @ R_N), np.einsum("nij,nj->ni", R_Mt, t_N - t_M)

    params0 = np.concatenate([np.zeros(3), t_X0_m, np.zeros(3), Y0[:3, 3]])
    return _gauss_newton(residuals, params0, 3 * len(T_wa_a) - 6)


def fit_handeye(motions: Motions, method: str = "park") -> HandEyeFit:
    """Closed form (``method``: park or tsai) + least-squares translation, then the joint refinement
    on poses when the motions came from poses, on the motions otherwise. BLAS on one thread: the
    Gauss-Newton steps are small and serial, more threads only spin."""
    if method not in METHODS:
        raise ValueError(f"unknown hand-eye method {method!r}; expected one of {', '.join(METHODS)}")
    with single_threaded():
        return _fit_handeye(motions, method)


def _fit_handeye(motions: Motions, method: str) -> HandEyeFit:
    a, b = motions.rotvec_A_rad, motions.rotvec_B_rad
    R_X0 = solve_rotation_park(a, b) if method == "park" else solve_rotation_tsai(a, b)
    t_X0 = solve_translation(motions, R_X0)
    if motions.T_wa_a is not None and motions.T_wb_b is not None:
        model, sol = "poses", refine_poses(motions.T_wa_a, motions.T_wb_b, R_X0, t_X0)
    else:
        model, sol = "motions", refine_motions(motions, R_X0, t_X0)
    R_X, t_X = _x_of(sol.params, R_X0)
    rot, trans = motion_residuals(motions, R_X, t_X)
    reason = None
    if sol.singular:
        reason = "the data leave a direction of X unconstrained"
    elif motions.n < 2:
        reason = "one motion has no redundancy: no residual scatter to scale an uncertainty with"
    covariance = None if reason or sol.covariance is None else sol.covariance[:6, :6]
    return HandEyeFit(
        se3.transform(R_X, t_X),
        method,
        model,
        rot,
        trans,
        sol.sigma_rot,
        sol.sigma_t,
        covariance,
        reason,
        sol.iterations,
    )
