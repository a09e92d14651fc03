"""Re-test a stored calibration on fresh board views without re-solving it.

Each fresh view's board pose is fitted with cv2.solvePnP with the stored K and distortion frozen
(``validation.refit_pose``, the very step that produced the calibration's held-out RMS), so
the fresh residuals and the stored held-out residuals have the same definition and, for an unchanged
camera, the same expected mean square. The verdict is a variance-ratio test: under "unchanged" with
Gaussian corner noise, ln(rms_check^2 / rms_ref^2) is close to normal with variance
2/d_check + 2/d_ref (d = scalar residuals minus 6 pose parameters per view), so

    limit = exp(z * 0.5 * sqrt(2/d_check + 2/d_ref)),   z = the (1 - alpha/tests) normal quantile.

One test overall plus one per radius ring and image octant that holds enough corners on both sides;
alpha is shared across them (Bonferroni), so the false-fail rate of the whole check stays <= alpha.
A focal change or a principal-point shift cannot be absorbed by a rigid pose on tilted views and
shows as a ratio above the limit (BENCHMARKS.md section "check"). A wrong metric scale (seed
chapter 0) leaves no residual at all: only a known distance catches it (``distance_ratio``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import cv2
import numpy as np

from calibctl.core.validation import N_OCTANTS, N_RINGS, refit_pose, residual_breakdown

DEFAULT_ALPHA = 0.005  # whole-check false-fail probability under the noise model (target <= 1 %)
MIN_REGION_CORNERS = 30  # fewer corners in a region (fresh or stored) and it is reported, not tested
POSE_PARAMETERS = 6


@dataclass(frozen=True)
class Reference:
    """The calibration's own held-out numbers the fresh residuals are compared with.

    Attributes:
        rms_px: held-out RMS over all corners. n_corners, n_views: what it was measured on.
        ring_edges_px: (4,) radius ring edges from the principal point, or None (no ring tests).
        ring_rms_px, ring_counts: (5,) held-out RMS and corners per ring (nan / 0 when unknown).
        octant_rms_px, octant_counts: (8,) the same per image octant.
    """

    rms_px: float
    n_corners: int
    n_views: int
    ring_edges_px: np.ndarray | None
    ring_rms_px: np.ndarray
    ring_counts: np.ndarray
    octant_rms_px: np.ndarray
    octant_counts: np.ndarray


@dataclass(frozen=True)
class RegionVerdict:
    """One tested (or only reported) region: ``overall``, ``ring N`` or ``octant N``."""

    region: str
    check_rms_px: float
    reference_rms_px: float
    ratio: float
    limit: float
    n_corners: int
    tested: bool

    @property
    def passed(self) -> bool:
        return not self.tested or self.ratio <= self.limit


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


@dataclass(frozen=True)
class RecheckResult:
    """Fresh residuals against a stored model.

    Attributes:
        view_rms_px: (V,) per-view RMS. rvecs, tvecs_m: (V, 3) fitted T_cam_board.
        board_distance_m: (V,) distance from the camera centre to the centre of the corners seen, metres.
        regions: overall first, then rings, then octants.
    """

    view_rms_px: np.ndarray
    rvecs: np.ndarray
    tvecs_m: np.ndarray
    board_distance_m: np.ndarray
    regions: tuple[RegionVerdict, ...]
    shifts: tuple[ParameterShift, ...]
    alpha: float

    @property
    def overall(self) -> RegionVerdict:
        return self.regions[0]

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.regions) and all(p.passed for p in self.shifts)

    @property
    def failed_regions(self) -> list[RegionVerdict]:
        return [r for r in self.regions if not r.passed]

    @property
    def failed_shifts(self) -> list[ParameterShift]:
        return [p for p in self.shifts if not p.passed]


def _dof(n_corners: float, n_views: int) -> float:
    """Scalar residuals left after each view's pose fit (never below 1)."""
    return max(2.0 * n_corners - POSE_PARAMETERS * n_views, 1.0)


def ratio_limit(dof_check: float, dof_reference: float, alpha: float) -> float:
    """Largest RMS ratio (check / reference) that is not a failure at one-sided level ``alpha``."""
    z = NormalDist().inv_cdf(1.0 - alpha)
    return math.exp(z * 0.5 * math.sqrt(2.0 / dof_check + 2.0 / dof_reference))


def _rms(res: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) if len(res) else float("nan")


def recheck(object_points_per_view: Sequence[np.ndarray], image_points_per_view: Sequence[np.ndarray],
            camera_matrix: np.ndarray, dist_coeffs: np.ndarray, image_size: tuple[int, int],
            reference: Reference, stored_sigma: dict[str, float], alpha: float = DEFAULT_ALPHA) -> RecheckResult:
    """Fit each fresh view's pose with the stored model and test its residuals against ``reference``.

    Args:
        object_points_per_view: V arrays (N_i, 3) float64 board frame, metres.
        image_points_per_view: V arrays (N_i, 2) float64 detected corners, px.
        camera_matrix: (3, 3) stored K, px. dist_coeffs: (n,) stored distortion, OpenCV order.
        image_size: (W, H) px of both the calibration and the fresh views.
        reference: the calibration's held-out numbers. alpha: whole-check false-fail level, half
            shared by the region tests, half by the parameter tests.
        stored_sigma: the calibration's one-sigma of ``focal`` (relative), ``cx`` and ``cy`` (px).

    Raises:
        NumericalError: solvePnP could not fit a view (from validation.refit_pose).
    """
    K = np.asarray(camera_matrix, np.float64)
    D = np.asarray(dist_coeffs, np.float64).ravel()
    residuals, rvecs, tvecs, distances = [], [], [], []
    for obj, img in zip(object_points_per_view, image_points_per_view, strict=True):
        res, rvec, tvec = refit_pose(obj, img, K, D)
        residuals.append(res)
        rvecs.append(rvec)
        tvecs.append(tvec)
        R = _rotation(rvec)
        distances.append(float(np.linalg.norm(R @ np.asarray(obj, np.float64).reshape(-1, 3).mean(axis=0) + tvec)))
    n_views = len(residuals)
    all_res = np.concatenate(residuals)
    cx, cy = float(K[0, 2]), float(K[1, 2])
    edges = reference.ring_edges_px if reference.ring_edges_px is not None else np.zeros(N_RINGS - 1)
    parts = residual_breakdown(image_points_per_view, residuals, (cx, cy), image_size, edges)
    candidates = [("overall", _rms(all_res), reference.rms_px, len(all_res), reference.n_corners)]
    if reference.ring_edges_px is not None:
        candidates += [(f"ring {i + 1}", float(parts.ring_rms_px[i]), float(reference.ring_rms_px[i]),
                        int(parts.ring_counts[i]), int(reference.ring_counts[i])) for i in range(N_RINGS)]
    candidates += [(f"octant {i}", float(parts.octant_rms_px[i]), float(reference.octant_rms_px[i]),
                    int(parts.octant_counts[i]), int(reference.octant_counts[i])) for i in range(N_OCTANTS)]
    testable = [c for c in candidates if _testable(c)]
    per_test = alpha / 2 / max(len(testable), 1)
    share_check = n_views / max(len(all_res), 1)  # pose parameters charged per corner
    share_ref = reference.n_views / max(reference.n_corners, 1)
    regions = []
    for c in candidates:
        name, rms, ref_rms, n, n_ref = c
        tested = c in testable
        limit = ratio_limit(_dof(n, round(n * share_check)), _dof(n_ref, round(n_ref * share_ref)), per_test)
        ratio = rms / ref_rms if tested else float("nan")
        regions.append(RegionVerdict(name, rms, ref_rms, ratio, limit, n, tested))
    shifts = intrinsic_shifts(object_points_per_view, image_points_per_view, K, D, rvecs, tvecs, residuals,
                              stored_sigma, alpha / 2)
    return RecheckResult(np.array([_rms(r) for r in residuals]), np.array(rvecs), np.array(tvecs),
                         np.array(distances), tuple(regions), shifts, alpha)


SHIFT_NAMES = ("focal", "cx", "cy")  # tested; k1 and k2 are estimated alongside as nuisance parameters


def intrinsic_shifts(object_points_per_view: Sequence[np.ndarray], image_points_per_view: Sequence[np.ndarray],
                     camera_matrix: np.ndarray, dist_coeffs: np.ndarray, rvecs: Sequence[np.ndarray],
                     tvecs: Sequence[np.ndarray], residuals_px: Sequence[np.ndarray],
                     stored_sigma: dict[str, float], alpha: float) -> tuple[ParameterShift, ...]:
    """One Gauss-Newton step of (focal scale, cx, cy, k1, k2) from the fresh residuals, poses eliminated.

    The step is a score test of "the stored model is right": it is measured, never applied. The pose
    columns of each view's Jacobian are projected out (Schur complement), so what a rigid pose can
    absorb (most of a focal change on a square-on view) is not counted. Noise is estimated from the
    fresh residuals themselves. Returns focal (relative), cx and cy (px) with their combined sigma.
    """
    K = np.asarray(camera_matrix, np.float64)
    D = np.asarray(dist_coeffs, np.float64).ravel()
    n_par = 5
    A = np.zeros((n_par, n_par))
    b = np.zeros(n_par)
    ssr, n_obs, n_pose = 0.0, 0, 0
    for obj, rvec, tvec, res in zip(object_points_per_view, rvecs, tvecs, residuals_px, strict=True):
        _, jac = cv2.projectPoints(np.asarray(obj, np.float64).reshape(-1, 3), rvec, tvec, K, D)
        J_pose = jac[:, :6]
        J_int = np.column_stack([K[0, 0] * jac[:, 6] + K[1, 1] * jac[:, 7], jac[:, 8], jac[:, 9],
                                 jac[:, 10], jac[:, 11]])
        r = np.asarray(res, np.float64).reshape(-1)  # u0, v0, u1, v1, ... as the Jacobian's rows
        J_perp = J_int - J_pose @ np.linalg.lstsq(J_pose, J_int, rcond=None)[0]
        r_perp = r - J_pose @ np.linalg.lstsq(J_pose, r, rcond=None)[0]
        A += J_perp.T @ J_perp
        b += J_perp.T @ r_perp
        ssr += float(r @ r)
        n_obs += r.size
        n_pose += POSE_PARAMETERS
    sigma2 = ssr / max(n_obs - n_pose - n_par, 1)
    try:
        cov = sigma2 * np.linalg.inv(A)
        step = np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return ()  # the fresh views do not constrain the intrinsics at all (e.g. one square-on view)
    z_limit = NormalDist().inv_cdf(1.0 - alpha / (2 * len(SHIFT_NAMES)))
    return tuple(ParameterShift(name, float(step[i]), math.hypot(math.sqrt(max(cov[i, i], 0.0)),
                                                                  stored_sigma.get(name, 0.0)), z_limit)
                 for i, name in enumerate(SHIFT_NAMES))


def _testable(c: tuple[str, float, float, int, int]) -> bool:
    _, rms, ref_rms, n, n_ref = c
    return (n >= MIN_REGION_CORNERS and n_ref >= MIN_REGION_CORNERS
            and math.isfinite(rms) and math.isfinite(ref_rms) and ref_rms > 0)


def _rotation(rvec: np.ndarray) -> np.ndarray:
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))
    return np.asarray(R)


def distance_ratio(board_distance_m: np.ndarray, reference_m: float) -> tuple[float, float]:
    """(median recovered / reference, relative spread of the recovered distances: (max - min) / median)."""
    d = np.asarray(board_distance_m, np.float64)
    median = float(np.median(d))
    return median / reference_m, float((d.max() - d.min()) / median)
