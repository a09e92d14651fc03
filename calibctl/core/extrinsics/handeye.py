"""Hand-eye calibration, A X = X B (seed chapter 2), numpy + OpenCV only.

Two sensors rigidly attached to one body see the same motion in their own frames. With
``X = T_a_b`` (maps points of sensor b's frame into sensor a's frame), ``A_i = T_a0_a1`` and
``B_i = T_b0_b1`` the motions of a and b over the same interval, rigidity gives ``A_i X = X B_i``.
Split into (rotation) ``R_A R_X = R_X R_B`` and (translation) ``(R_A - I) t_X = R_X t_B - t_A``:

- Park & Martin: ``log(R_A) = R_X log(R_B)`` is an orthogonal Procrustes problem on the motions'
  axis-angle vectors, ``M = sum a_i b_i^T = U S V^T``, ``R_X = U diag(1, 1, det(U V^T)) V^T`` (the
  det guard turns a reflection into the rotation the data cannot pin down).
- Tsai & Lenz: linear least squares on the modified Rodrigues vectors 2 sin(theta/2) n.
- Then the translation by linear least squares, and a joint Gauss-Newton refinement of all six
  parameters on per-motion residuals weighted by their own scatter; the covariance of the result
  comes from the same weighted Jacobian (rotation as a left perturbation in frame a, radians; t in m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics import se3

METHODS = ("park", "tsai")
RESIDUAL_FLOOR = 1e-12  # exact (noise-free) data: weights stay finite and the covariance is ~0
JACOBIAN_STEP = 1e-6  # central differences in rad / m
SINGULAR_RCOND = 1e-10  # J^T J eigenvalues below this * largest: a direction the data does not see


@dataclass(frozen=True)
class Motions:
    """n synchronised relative motions of sensors a and b.

    Attributes:
        R_A: (n, 3, 3) rotation of ``T_a0_a1``; t_A_m: (n, 3) its translation, metres.
        R_B: (n, 3, 3) rotation of ``T_b0_b1``; t_B_m: (n, 3) its translation, metres.
        labels: (n,) how each motion is named in messages, e.g. "rows 3-4".
    """

    R_A: np.ndarray
    t_A_m: np.ndarray
    R_B: np.ndarray
    t_B_m: np.ndarray
    labels: tuple[str, ...]

    @property
    def n(self) -> int:
        return int(self.R_A.shape[0])

    @classmethod
    def from_transforms(cls, T_a0_a1: np.ndarray, T_b0_b1: np.ndarray, labels: tuple[str, ...]) -> Motions:
        """(n, 4, 4) relative motions of a and b."""
        A, B = np.asarray(T_a0_a1, np.float64), np.asarray(T_b0_b1, np.float64)
        return cls(A[:, :3, :3], A[:, :3, 3], B[:, :3, :3], B[:, :3, 3], labels)

    @classmethod
    def from_poses(cls, T_wa_a: np.ndarray, T_wb_b: np.ndarray, labels: tuple[str, ...], prefix: str = "") -> Motions:
        """(n, 4, 4) poses of a in a fixed world wa and of b in a fixed world wb -> n-1 consecutive motions.

        ``labels`` names the poses; motion i is labelled "<label i>-<label i+1>" (with ``prefix`` before it).
        """
        A = [se3.relative(T_wa_a[i], T_wa_a[i + 1]) for i in range(len(T_wa_a) - 1)]
        B = [se3.relative(T_wb_b[i], T_wb_b[i + 1]) for i in range(len(T_wb_b) - 1)]
        names = tuple(f"{prefix}{labels[i]}-{labels[i + 1]}" for i in range(len(labels) - 1))
        return cls.from_transforms(np.array(A).reshape(-1, 4, 4), np.array(B).reshape(-1, 4, 4), names)

    @property
    def rotvec_A_rad(self) -> np.ndarray:
        """(n, 3) axis-angle vectors a_i = log(R_A,i)."""
        return se3.rotvecs_from_rotations(self.R_A)

    @property
    def rotvec_B_rad(self) -> np.ndarray:
        return se3.rotvecs_from_rotations(self.R_B)


def solve_rotation_park(rotvec_A_rad: np.ndarray, rotvec_B_rad: np.ndarray) -> np.ndarray:
    """Park & Martin: R_X maximising sum a_i . R_X b_i. (n, 3), (n, 3) -> (3, 3) rotation (det +1)."""
    M = np.asarray(rotvec_A_rad, np.float64).T @ np.asarray(rotvec_B_rad, np.float64)  # sum a_i b_i^T
    U, _, Vt = np.linalg.svd(M)
    guard = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])  # a reflection is not a rotation
    return U @ guard @ Vt


def solve_rotation_tsai(rotvec_A_rad: np.ndarray, rotvec_B_rad: np.ndarray) -> np.ndarray:
    """Tsai & Lenz: skew(p_a + p_b) p' = p_b - p_a with p = 2 sin(theta/2) n, then R_X from p'.

    Not defined for a 180 deg R_X (p' is tan(theta_X/2) n_X).
    """
    def modified(rotvec: np.ndarray) -> np.ndarray:
        angle = np.linalg.norm(rotvec, axis=1, keepdims=True)
        return np.where(angle > 0, 2.0 * np.sin(angle / 2.0) / np.where(angle > 0, angle, 1.0), 1.0) * rotvec

    p_a, p_b = modified(np.asarray(rotvec_A_rad, np.float64)), modified(np.asarray(rotvec_B_rad, np.float64))
    lhs = np.vstack([se3.skew(a + b) for a, b in zip(p_a, p_b, strict=True)])
    p_prime = np.linalg.lstsq(lhs, (p_b - p_a).reshape(-1), rcond=None)[0]
    p = 2.0 * p_prime / np.sqrt(1.0 + p_prime @ p_prime)
    sq = float(p @ p)
    return (1.0 - sq / 2.0) * np.eye(3) + 0.5 * (np.outer(p, p) + np.sqrt(4.0 - sq) * se3.skew(p))


def solve_translation(motions: Motions, R_X: np.ndarray) -> np.ndarray:
    """Least squares of the stacked (R_A - I) t_X = R_X t_B - t_A -> (3,) t_X, metres.

    Minimum-norm along directions the motions do not excite (the gate refuses those beforehand).
    """
    lhs = (motions.R_A - np.eye(3)).reshape(-1, 3)
    rhs = (motions.t_B_m @ R_X.T - motions.t_A_m).reshape(-1)
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0]


def lever_arm_sigma_m(R_A: np.ndarray, sigma_motion_translation_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Error propagation of the translation solve: lever-arm one-sigma along each excited direction.

    An error sigma in every motion translation becomes sigma / s_k along the k-th right-singular
    vector of the stacked (R_A - I) (in 2-D one motion of theta gives s = 2 sin(theta/2)).

    Returns:
        (3,) sigma in metres (inf where s_k = 0), (3, 3) the directions as rows, strongest first.
    """
    _, s, Vt = np.linalg.svd((np.asarray(R_A, np.float64) - np.eye(3)).reshape(-1, 3))
    with np.errstate(divide="ignore"):
        sigma = np.where(s > 1e-12, sigma_motion_translation_m / np.maximum(s, 1e-300), np.inf)
    return sigma, Vt


def motion_residuals(motions: Motions, R_X: np.ndarray, t_X_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-motion misfit of A X = X B: (n, 3) log(R_A R_X R_B^T R_X^T) in rad, (n, 3) translation in m."""
    rot = se3.rotvecs_from_rotations(motions.R_A @ R_X @ motions.R_B.transpose(0, 2, 1) @ R_X.T)
    trans = (motions.R_A - np.eye(3)) @ t_X_m - motions.t_B_m @ R_X.T + motions.t_A_m
    return rot, trans


@dataclass(frozen=True)
class HandEyeFit:
    """The refined X = T_a_b with its uncertainty and per-motion residuals.

    covariance: (6, 6) over (rotation perturbation in frame a, rad; translation, m), or None with
    ``refused_reason`` when the data leave a direction unconstrained or have no redundancy.
    """

    T_a_b: np.ndarray
    method: str
    residual_rotation_rad: np.ndarray  # (n, 3)
    residual_translation_m: np.ndarray  # (n, 3)
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


def _group_sigma(residual: np.ndarray, dof: int) -> float:
    return max(float(np.sqrt(np.sum(residual**2) / max(dof, 1))), RESIDUAL_FLOOR)


def _weighted(motions: Motions, R0: np.ndarray, params: np.ndarray, w_rot: float, w_t: float) -> np.ndarray:
    R_X = se3.rotation_from_rotvec(params[:3]) @ R0
    rot, trans = motion_residuals(motions, R_X, params[3:])
    return np.concatenate([(rot * w_rot).ravel(), (trans * w_t).ravel()])


def _jacobian(motions: Motions, R0: np.ndarray, params: np.ndarray, w_rot: float, w_t: float) -> np.ndarray:
    cols = []
    for k in range(6):
        step = np.zeros(6)
        step[k] = JACOBIAN_STEP
        cols.append((_weighted(motions, R0, params + step, w_rot, w_t)
                     - _weighted(motions, R0, params - step, w_rot, w_t)) / (2 * JACOBIAN_STEP))
    return np.column_stack(cols)


def refine(motions: Motions, R_X0: np.ndarray, t_X0_m: np.ndarray, method: str, max_iterations: int = 20) -> HandEyeFit:
    """Joint Gauss-Newton on rotation and translation; each residual group weighted by 1/its RMS.

    The weights are re-estimated every iteration (dof 3n - 3 per group), so the covariance
    s^2 (J^T J)^-1 is in the units of the data's own scatter: honest when motion errors are
    independent from motion to motion.
    """
    R0 = np.asarray(R_X0, np.float64)
    params = np.concatenate([np.zeros(3), np.asarray(t_X0_m, np.float64)])
    dof = 3 * motions.n - 3
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 - the count is reported
        rot, trans = motion_residuals(motions, se3.rotation_from_rotvec(params[:3]) @ R0, params[3:])
        w_rot, w_t = 1.0 / _group_sigma(rot, dof), 1.0 / _group_sigma(trans, dof)
        J = _jacobian(motions, R0, params, w_rot, w_t)
        step = np.linalg.lstsq(J, -_weighted(motions, R0, params, w_rot, w_t), rcond=None)[0]
        params = params + step
        if np.max(np.abs(step)) < 1e-12:
            break
    R_X = se3.rotation_from_rotvec(params[:3]) @ R0
    rot, trans = motion_residuals(motions, R_X, params[3:])
    s_rot, s_t = _group_sigma(rot, dof), _group_sigma(trans, dof)
    J = _jacobian(motions, R_X, np.concatenate([np.zeros(3), params[3:]]), 1.0 / s_rot, 1.0 / s_t)
    information = J.T @ J
    eig = np.linalg.eigvalsh(information)
    covariance, reason = None, None
    if motions.n < 2:
        reason = "one motion has no redundancy: no residual scatter to scale an uncertainty with"
    elif eig[0] <= SINGULAR_RCOND * eig[-1]:
        reason = "the motions leave a direction of X unconstrained"
    else:
        covariance = np.linalg.inv(information)
    return HandEyeFit(se3.transform(R_X, params[3:]), method, rot, trans, s_rot, s_t, covariance, reason, it)


def fit_handeye(motions: Motions, method: str = "park") -> HandEyeFit:
    """Closed-form start (``method``: park or tsai), translation by least squares, joint refinement."""
    if method not in METHODS:
        raise ValueError(f"unknown hand-eye method {method!r}; expected one of {', '.join(METHODS)}")
    a, b = motions.rotvec_A_rad, motions.rotvec_B_rad
    R_X = solve_rotation_park(a, b) if method == "park" else solve_rotation_tsai(a, b)
    return refine(motions, R_X, solve_translation(motions, R_X), method)
