"""One Levenberg-Marquardt solver for calibctl's own least-squares problems: dense, or Schur over per-view
blocks.

It lives at the top of core, beside ``gate`` and ``blas_threads``, because intrinsics and extrinsics both
solve with it and neither room may import the other.

The problem hands over its Gauss-Newton normal equations at a point: ``cost = r^T r`` (the residual sum
of squares, in the residuals' squared units, e.g. px^2), ``H = J^T J`` and ``g = J^T r``, where ``r`` is
observed - predicted and ``J = d(predicted)/d(params)``; the step ``delta`` then solves
``(H + lam * diag(H)) delta = g`` (Marquardt's scaling: each parameter damped in its own units; a zero
diagonal counts as 1e-12) and the caller's ``retract(params, delta)`` applies it. Two forms:

- ``DenseSystem``: ``H`` (n, n) and ``g`` (n,) over every free parameter (a single pose).
- ``SchurSystem``: shared parameters (p of them, first in ``delta``) and V blocks of k parameters that
  touch only their own rows (one board pose per view or frame: the fisheye and rig problems; built from
  per-block Jacobians, or regrouped from dense normal equations by ``from_dense``). The blocks are eliminated
  (the Schur complement ``S = A - sum_v B_v C_v^-1 B_v^T``), the p shared parameters solved, the blocks
  back-substituted: V k x k solves and one p x p instead of one (p + Vk)^2 system. The damped Schur step
  equals the dense step of the same system (tests/core/test_lm.py holds them to 1e-10).

Schedule (``Damping``): start at ``initial``; a step is accepted when the cost at the trial is finite and
not higher, then lam /= ``decrease`` (not below ``floor``); otherwise, or when the damped system cannot
be solved, lam *= ``increase``. Stops: a trial changed the cost by less than ``relative_tolerance`` of
it (lowered: the step is kept; raised: rounding at the minimum, the step is dropped), or a step is
smaller than ``step_tolerance`` (all three: converged); lam passed ``ceiling`` (no step lowers the cost);
``max_iterations`` tries (accepted or not). Each caller keeps the schedule and tolerances its own loop
had before it moved here (fisheye: lam /3 and x4, floor 1e-9, ceiling 1e8; rig: x10 both ways), so its
answers did not move beyond rounding.

Users: ``core.intrinsics.fisheye_solve`` and ``core.extrinsics.rig_solve`` (Schur: 8 lens parameters,
or the camera poses and intrinsics, shared; one 6-parameter board pose per view or frame),
``core.intrinsics.fisheye_model.refine_fisheye_pose`` and ``core.extrinsics.rig_validation.fit_board_pose``
(dense, six pose parameters). Not users, each for a reason written in its own docstring:
``core.extrinsics.handeye_refine`` re-weights its residual groups every iteration (the cost being
minimised changes from one iteration to the next, so an accept/reject rule on it means nothing) and
takes SVD least-squares steps on J, not on the normal equations;
``core.check.recheck_delta`` takes one Gauss-Newton step as a score test and never applies it; the pinhole
board pose (``core.extrinsics.board_pose``), every pinhole intrinsic solve and the two-camera pinhole rig
use OpenCV's own LM (cv2.solvePnPRefineLM, cv2.calibrateCamera, cv2.stereoCalibrateExtended).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from calibctl.errors import NumericalError

P = TypeVar("P")
MIN_DIAGONAL = 1e-12  # damping weight of a parameter whose column is all zero (it moves only by damping)


@dataclass(frozen=True)
class Damping:
    """Marquardt damping schedule (module docstring); unitless multipliers of diag(H)."""

    initial: float = 1e-3
    decrease: float = 10.0
    increase: float = 10.0
    floor: float = 1e-12
    ceiling: float = 1e12


@dataclass(frozen=True)
class DenseSystem:
    """Normal equations over n parameters: cost = r^T r, H = J^T J (n, n), g = J^T r (n,)."""

    cost: float
    H: np.ndarray
    g: np.ndarray

    @classmethod
    def from_jacobian(cls, J: np.ndarray, r: np.ndarray) -> DenseSystem:
        """From J (m, n) = d(predicted)/d(params) and r (m,) = observed - predicted."""
        return cls(float(r @ r), J.T @ J, J.T @ r)

    def finite(self) -> bool:
        return math.isfinite(self.cost) and bool(np.isfinite(self.H).all() and np.isfinite(self.g).all())


@dataclass(frozen=True)
class SchurSystem:
    """Normal equations over p shared parameters and V blocks of k; delta = [shared (p,), block 0 (k,), ...].

    Attributes:
        cost: r^T r. A: (p, p) shared x shared. g_shared: (p,). B: (V, p, k) shared x block v.
        C: (V, k, k) block v x block v. g_blocks: (V, k).
    """

    cost: float
    A: np.ndarray
    g_shared: np.ndarray
    B: np.ndarray
    C: np.ndarray
    g_blocks: np.ndarray

    @classmethod
    def from_jacobians(cls, blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> SchurSystem:
        """From per block (J_shared (m_v, p), J_block (m_v, k), r (m_v,)): block v's rows touch only block
        v."""
        J_s = [b[0] for b in blocks]
        J_b = [b[1] for b in blocks]
        rs = [b[2] for b in blocks]
        return cls(
            float(sum(float(r @ r) for r in rs)),
            sum((J.T @ J for J in J_s), np.zeros((J_s[0].shape[1],) * 2)),
            sum((J.T @ r for J, r in zip(J_s, rs, strict=True)), np.zeros(J_s[0].shape[1])),
            np.array([Js.T @ Jb for Js, Jb in zip(J_s, J_b, strict=True)]),
            np.array([Jb.T @ Jb for Jb in J_b]),
            np.array([Jb.T @ r for Jb, r in zip(J_b, rs, strict=True)]),
        )

    @classmethod
    def from_dense(cls, system: DenseSystem, shared: np.ndarray, blocks: np.ndarray) -> SchurSystem:
        """Regroup dense normal equations: shared (p,) and blocks (V, k) index H's rows; every other
        pair of blocks must be uncoupled in H (zero). delta[:p] then belongs to ``shared``, delta[p:] to
        ``blocks.ravel()``."""
        H, g = system.H, system.g
        B = H[shared][:, blocks].transpose(1, 0, 2)  # (V, p, k)
        C = H[blocks[:, :, None], blocks[:, None, :]]  # (V, k, k)
        return cls(system.cost, H[np.ix_(shared, shared)], g[shared], B, C, g[blocks])

    def finite(self) -> bool:
        return math.isfinite(self.cost) and all(
            bool(np.isfinite(a).all()) for a in (self.A, self.g_shared, self.B, self.C, self.g_blocks)
        )

    def dense(self) -> DenseSystem:
        """The same equations as one (p + Vk) system (for tests and small problems)."""
        p, (V, k) = self.A.shape[0], self.g_blocks.shape
        H = np.zeros((p + V * k, p + V * k))
        H[:p, :p] = self.A
        for v in range(V):
            at = slice(p + v * k, p + (v + 1) * k)
            H[:p, at], H[at, :p], H[at, at] = self.B[v], self.B[v].T, self.C[v]
        return DenseSystem(self.cost, H, np.concatenate([self.g_shared, self.g_blocks.ravel()]))


System = DenseSystem | SchurSystem


@dataclass(frozen=True)
class LMResult(Generic[P]):
    """params: the last accepted point. cost: r^T r there. iterations: steps tried (accepted or not).
    converged: the relative cost or the step rule stopped it. stop: "cost", "step", "damping" (lam passed
    the ceiling) or "iterations"."""

    params: P
    cost: float
    iterations: int
    converged: bool
    stop: str


def _damp(diagonal: np.ndarray, lam: float) -> np.ndarray:
    return lam * np.maximum(diagonal, MIN_DIAGONAL)


def damped_step(system: System, lam: float) -> np.ndarray:
    """delta solving (H + lam diag(H)) delta = g, flat as the system's layout.

    Raises:
        np.linalg.LinAlgError: the damped system is singular (``solve_lm`` raises the damping).
    """
    if isinstance(system, DenseSystem):
        H = system.H + np.diag(_damp(np.diag(system.H), lam))
        return np.linalg.solve(H, system.g)
    A, B, C = system.A, system.B, system.C
    p, k = A.shape[0], C.shape[1]
    C_damped = C + _damp(np.diagonal(C, axis1=1, axis2=2), lam)[:, :, None] * np.eye(k)
    both = np.linalg.solve(
        C_damped, np.concatenate([B.transpose(0, 2, 1), system.g_blocks[:, :, None]], axis=2)
    )
    Cinv_Bt, Cinv_g = both[:, :, :p], both[:, :, p]
    S = A + np.diag(_damp(np.diag(A), lam)) - np.einsum("vpk,vkq->pq", B, Cinv_Bt)
    d_shared = np.linalg.solve(S, system.g_shared - np.einsum("vpk,vk->p", B, Cinv_g))
    d_blocks = Cinv_g - np.einsum("vkp,p->vk", Cinv_Bt, d_shared)
    return np.concatenate([d_shared, d_blocks.ravel()])


def solve_lm(
    evaluate: Callable[[P], System],
    start: P,
    retract: Callable[[P, np.ndarray], P],
    *,
    damping: Damping = Damping(),
    max_iterations: int = 100,
    relative_tolerance: float = 1e-12,
    step_tolerance: float = 0.0,
    label: str = "the least-squares solve",
    hint: str | None = None,
) -> LMResult[P]:
    """Minimise r^T r from ``start`` (module docstring).

    Args:
        evaluate: params -> the normal equations there (``DenseSystem`` or ``SchurSystem``, one form per
        problem). start: the initial parameters, any type ``retract`` understands.
        retract: (params, delta) -> params moved by delta (flat, the system's layout; e.g. params + delta).
        damping: the schedule. max_iterations: steps tried at most.
        relative_tolerance: stop once a trial changes the cost by less than this share of it (either way).
        step_tolerance: stop once a computed step's largest element is below this, in the parameters'
            units (0: off); the step is not applied (it only chases rounding).
        label, hint: name the problem in the error.

    Raises:
        NumericalError: the residuals or their derivatives are not finite at ``start`` (nothing to descend
        from).
    """
    params, system = start, evaluate(start)
    if not system.finite():
        raise NumericalError(
            f"{label} cannot start: its residuals or their derivatives are NaN or infinite at "
            "the initial values",
            hint=hint or "check the inputs and the initial values",
        )
    lam, it = damping.initial, 0
    for it in range(1, max_iterations + 1):
        try:
            delta: np.ndarray | None = damped_step(system, lam)
        except np.linalg.LinAlgError:
            delta = None
        if delta is not None and not np.isfinite(delta).all():
            delta = None
        if delta is not None and float(np.max(np.abs(delta), initial=0.0)) < step_tolerance:
            return LMResult(params, system.cost, it, True, "step")
        trial_params = retract(params, delta) if delta is not None else None
        trial = evaluate(trial_params) if trial_params is not None else None
        if trial is not None and trial.finite() and trial.cost <= system.cost:
            gain = (system.cost - trial.cost) / max(system.cost, 1e-300)
            params, system = trial_params, trial  # type: ignore[assignment]
            lam = max(lam / damping.decrease, damping.floor)
            if gain < relative_tolerance:
                return LMResult(params, system.cost, it, True, "cost")
        elif (
            trial is not None
            and trial.finite()
            and trial.cost - system.cost <= relative_tolerance * system.cost
        ):
            return LMResult(
                params, system.cost, it, True, "cost"
            )  # not lower, but only by rounding: the minimum
        else:
            lam *= damping.increase
            if lam > damping.ceiling:
                return LMResult(params, system.cost, it, False, "damping")
    return LMResult(params, system.cost, it, False, "iterations")
