"""Hand-eye calibration, A X = X B (seed chapter 2), numpy + OpenCV only.

Two sensors rigidly attached to one body see the same motion in their own frames. With
``X = T_a_b`` (maps points of sensor b's frame into sensor a's frame), ``A_i = T_a0_a1`` and
``B_i = T_b0_b1`` the motions of a and b over the same interval, rigidity gives ``A_i X = X B_i``.
Split into (rotation) ``R_A R_X = R_X R_B`` and (translation) ``(R_A - I) t_X = R_X t_B - t_A``:

- Park & Martin: ``log(R_A) = R_X log(R_B)`` is an orthogonal Procrustes problem on the motions'
  axis-angle vectors, ``M = sum a_i b_i^T = U S V^T``, ``R_X = U diag(1, 1, det(U V^T)) V^T`` (the
  det guard turns a reflection into the rotation the data cannot pin down).
- Tsai & Lenz: linear least squares on the modified Rodrigues vectors 2 sin(theta/2) n.
- Then the translation by linear least squares; ``handeye_refine`` refines all six parameters
  jointly and gives their covariance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics import se3

METHODS = ("park", "tsai")


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
    T_wa_a: np.ndarray | None = None  # (n + 1, 4, 4) the poses the motions came from, when they did
    T_wb_b: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.R_A.shape[0])

    @classmethod
    def from_transforms(cls, T_a0_a1: np.ndarray, T_b0_b1: np.ndarray, labels: tuple[str, ...]) -> Motions:
        """(n, 4, 4) relative motions of a and b."""
        A, B = np.asarray(T_a0_a1, np.float64), np.asarray(T_b0_b1, np.float64)
        return cls(A[:, :3, :3], A[:, :3, 3], B[:, :3, :3], B[:, :3, 3], labels)

    @classmethod
    def from_poses(
        cls, T_wa_a: np.ndarray, T_wb_b: np.ndarray, labels: tuple[str, ...], prefix: str = ""
    ) -> Motions:
        """(n, 4, 4) poses of a in a fixed world wa and of b in a fixed world wb -> n-1 consecutive motions.

        ``labels`` names the poses; motion i is labelled "<label i>-<label i+1>" (with ``prefix`` before it).
        """
        A = np.array([se3.relative(T_wa_a[i], T_wa_a[i + 1]) for i in range(len(T_wa_a) - 1)]).reshape(
            -1, 4, 4
        )
        B = np.array([se3.relative(T_wb_b[i], T_wb_b[i + 1]) for i in range(len(T_wb_b) - 1)]).reshape(
            -1, 4, 4
        )
        names = tuple(f"{prefix}{labels[i]}-{labels[i + 1]}" for i in range(len(labels) - 1))
        return cls(
            A[:, :3, :3],
            A[:, :3, 3],
            B[:, :3, :3],
            B[:, :3, 3],
            names,
            np.asarray(T_wa_a, np.float64),
            np.asarray(T_wb_b, np.float64),
        )

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


def translation_scale(motions: Motions, R_X: np.ndarray) -> tuple[float, float]:
    """The scale s on a's translations that best fits the translation half, ``(R_A - I) t_X + s t_A = R_X
    t_B``.

    With R_X known the equation is linear in (t_X, s), so one least-squares solve gives s and its
    one-sigma (from the residual scatter, dof 3n - 4). Both sensors in metres: s = 1 within the noise;
    a's translations in millimetres: s = 0.001 (b's: 1000), whatever the lever arm turned out to be.

    Returns:
        (s, sigma_s); sigma_s is inf when the motions do not determine s (a never translates).
    """
    lhs = np.concatenate([(motions.R_A - np.eye(3)).reshape(-1, 3), motions.t_A_m.reshape(-1, 1)], axis=1)
    rhs = (motions.t_B_m @ R_X.T).reshape(-1)
    solution, _, rank, _ = np.linalg.lstsq(lhs, rhs, rcond=None)
    dof = lhs.shape[0] - lhs.shape[1]
    if rank < lhs.shape[1] or dof <= 0:
        return float(solution[3]), float("inf")
    variance = float(np.sum((lhs @ solution - rhs) ** 2)) / dof
    sigma = float(np.sqrt(max(variance, 0.0) * np.linalg.inv(lhs.T @ lhs)[3, 3]))
    return float(solution[3]), sigma


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
