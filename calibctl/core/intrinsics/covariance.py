"""Covariance of the intrinsic parameters of a solve, from the Jacobian at the solution.

Why not just OpenCV's stdDeviationsIntrinsics: OpenCV inverts the full (intrinsics + 6 per view)
normal matrix with a pseudo-inverse in raw units, where focal lengths (~1e3 px), distortion (~1)
and translations (~1e-1 m) differ by many orders of magnitude. When the views barely constrain the
focal length (board tilt under ~1.5 deg, the seed's failure mode A) the pseudo-inverse drops the
weak direction instead of reporting it: measured on synthetic 8-view sessions with 0-1.5 deg tilt,
OpenCV reported sigma(fx) = 0.002 px while fx came out at 1260 or 8780 px for a true 800 px
(tests/core/intrinsics/test_solve.py::test_sigma_is_not_fooled_by_a_fronto_parallel_capture). The sigma(fx)
< 2 px lint would pass those.

Here: per view, J from cv2.projectPoints (columns rvec, tvec, fx, fy, cx, cy, distortion); pose
parameters are eliminated by the Schur complement (each view's 6 pose parameters touch only its own
rows), which leaves the p x p reduced information matrix S of the free intrinsics (p <= 11).
S is scaled to unit diagonal, and its reciprocal condition number decides observability
(MIN_RCOND); the covariance is S^-1 * s^2 with s^2 = sum of squared residuals / (residuals -
parameters), the same noise estimate OpenCV uses. On well-posed data this agrees with OpenCV's
numbers to well under 1 % (tested).

Under CALIB_FIX_ASPECT_RATIO the focal length is one parameter f = fy with fx = a * fy: its Jacobian
column is a * dr/dfx + dr/dfy, and sigma(fx) = a * sigma(fy).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

# Reciprocal condition number of the unit-diagonal reduced information matrix below which a
# parameter combination is declared unobservable (double precision keeps ~16 digits; 1e-12 leaves
# room for the squared conditioning of normal equations).
MIN_RCOND = 1e-12
_DIST_COLUMN = {"k1": 0, "k2": 1, "p1": 2, "p2": 3, "k3": 4, "k4": 5, "k5": 6, "k6": 7}


@dataclass(frozen=True)
class IntrinsicCovariance:
    """Covariance of the free intrinsic parameters (poses marginalised).

    Attributes:
        names: parameter names in matrix order ("fy" is the tied focal length when aspect is set).
        covariance: (p, p) float64 in px^2 / unitless^2, or None when refused.
        rcond: reciprocal condition number of the scaled reduced information matrix.
        residual_variance_px2: s^2 per coordinate.
        refused_reason: set when the covariance is not meaningful.
    """

    names: tuple[str, ...]
    covariance: np.ndarray | None
    rcond: float
    residual_variance_px2: float
    refused_reason: str | None


def intrinsic_columns(J: np.ndarray, free_intrinsics: Sequence[str], free_distortion: Sequence[str],
                      aspect: float | None, distortion_order: Sequence[str] | None = None,
                      ) -> tuple[np.ndarray, tuple[str, ...]]:
    """Columns of a cv2.projectPoints Jacobian for the free intrinsics, and their names (fy tied when aspect).

    ``distortion_order`` names J's distortion columns (from column 10) when they are not OpenCV's pinhole
    order, e.g. a fisheye Jacobian rearranged as [rvec tvec fx fy cx cy k1 k2 k3 k4].
    """
    dist_column = _DIST_COLUMN if distortion_order is None else {n: i for i, n in enumerate(distortion_order)}
    cols, names = [], []
    for name in free_intrinsics:
        if name == "fx":
            if aspect is None:
                cols.append(J[:, 6])
                names.append("fx")
        elif name == "fy":
            cols.append(J[:, 7] + (aspect * J[:, 6] if aspect is not None else 0.0))
            names.append("fy")
        else:
            cols.append(J[:, 8] if name == "cx" else J[:, 9])
            names.append(name)
    for name in free_distortion:
        cols.append(J[:, 10 + dist_column[name]])
        names.append(name)
    return np.stack(cols, axis=1), tuple(names)


def intrinsic_covariance(
    object_points_per_view: Sequence[np.ndarray],
    rvecs: np.ndarray,
    tvecs: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    residuals_px_per_view: Sequence[np.ndarray],
    free_intrinsics: Sequence[str],
    free_distortion: Sequence[str],
    aspect: float | None,
    dof: int,
) -> IntrinsicCovariance:
    """Covariance of the free intrinsics at a solution.

    Args:
        object_points_per_view: V arrays (N_i, 3) float64 board frame.
        rvecs, tvecs: (V, 3) float64 solved poses. camera_matrix: (3, 3). dist_coeffs: (n,).
        residuals_px_per_view: V arrays (N_i, 2) float64 observed - projected.
        free_intrinsics, free_distortion: names (see solve.MODELS). aspect: fx/fy when tied.
        dof: residual count - free parameter count (> 0).
    """
    def blocks():
        for obj, r, t in zip(object_points_per_view, rvecs, tvecs, strict=True):
            _, J = cv2.projectPoints(np.asarray(obj, dtype=np.float64), r, t, camera_matrix, dist_coeffs)
            J_int, names = intrinsic_columns(J, free_intrinsics, free_distortion, aspect)
            yield J_int, J[:, :6], names

    return schur_covariance(blocks(), residuals_px_per_view, dof)


def schur_covariance(
    view_jacobians: Iterable[tuple[np.ndarray, np.ndarray, tuple[str, ...]]],
    residuals_px_per_view: Sequence[np.ndarray],
    dof: int,
) -> IntrinsicCovariance:
    """Covariance of the intrinsics from per-view Jacobians, each view's 6 pose parameters eliminated.

    Args:
        view_jacobians: per view (J_int (2N, p), J_pose (2N, 6), names of the p columns); any camera
            model (pinhole here, the fisheye model in calibctl.core.intrinsics.fisheye_solve).
        residuals_px_per_view: V arrays (N_i, 2) float64 observed - projected.
        dof: residual count - free parameter count (> 0).
    """
    S = None
    names: tuple[str, ...] = ()
    for J_int, J_pose, names in view_jacobians:
        C = J_pose.T @ J_pose
        B = J_int.T @ J_pose
        try:
            block = J_int.T @ J_int - B @ np.linalg.solve(C, B.T)
        except np.linalg.LinAlgError:
            return IntrinsicCovariance(names, None, 0.0, float("nan"),
                                       "a view's board pose is not determined by its corners")
        S = block if S is None else S + block
    assert S is not None
    ssr = sum(float(np.sum(np.asarray(res, dtype=np.float64) ** 2)) for res in residuals_px_per_view)
    s2 = ssr / dof
    S = 0.5 * (S + S.T)
    d = np.sqrt(np.clip(np.diag(S), 0.0, None))
    if not (np.isfinite(S).all() and np.all(d > 0)):
        return IntrinsicCovariance(names, None, 0.0, s2, "a parameter has no effect on the residuals")
    S_unit = S / np.outer(d, d)
    eig = np.linalg.eigvalsh(S_unit)
    rcond = float(eig[0] / eig[-1]) if eig[-1] > 0 else 0.0
    if not rcond >= MIN_RCOND:
        weakest = np.linalg.eigh(S_unit)[1][:, 0]
        main = [names[i] for i in np.argsort(-np.abs(weakest))[:2]]
        return IntrinsicCovariance(
            names, None, rcond, s2,
            f"the intrinsics are not observable from these views (reciprocal condition {rcond:.1e} "
            f"< {MIN_RCOND:.0e}; weakest combination mainly {' and '.join(main)})")
    cov = np.linalg.inv(S_unit) / np.outer(d, d) * s2
    return IntrinsicCovariance(names, 0.5 * (cov + cov.T), rcond, s2, None)
