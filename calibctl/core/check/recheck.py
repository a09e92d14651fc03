"""Re-test a stored calibration on fresh board views without re-solving it.

Each fresh view's board pose is fitted with the stored intrinsics and distortion frozen, through the
stored model's own projection (``validation.refit_pose``: pinhole or fisheye), the very step that
produced the calibration's held-out RMS, so the fresh and the stored residuals have one definition.

Two families of tests share the whole-check false-fail level ``alpha`` (Bonferroni between them):

1. **What a change does** (``core.check.recheck_delta``): a focal change or a principal-point shift leaves a
   systematic pattern that a rigid pose only partly absorbs. A small delta model (focal scale, cx, cy;
   k1, k2 as nuisance) is fitted to the fresh residuals with every view's pose free and each view
   weighted by its own noise (detector noise differs with tilt, distance and blur), and the delta is
   tested against the stored covariance plus the fresh estimate's: one z per parameter, two-sided,
   Bonferroni over the three. ``SHIFT_SHARE`` (80 %) of ``alpha``: this is the test with the power.
2. **How well the model fits** (variance ratio per region): under "unchanged", ln(ms_check / ms_ref) is
   close to normal with variance phi * (2/d_check + 2/d_ref), d = scalar residuals minus 6 per view.
   phi >= 1 is the between-view dispersion of the fresh mean squares (their cluster-robust variance
   over the iid one): rendered and real photos do not have equal noise in every view, so the corner
   count overstates what an RMS knows; the stored side is assumed to share the camera's phi. The
   overall test plus each ring and octant with enough corners, Holm step-down over them. The other 20 %.

A wrong metric scale (seed chapter 0) leaves no residual at all: only a known distance catches it
(``distance_ratio``). benchmarks/results/check.md has the measured false-fail and detection rates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from calibctl.core.check.recheck_delta import ParameterShift, intrinsic_shifts, stored_delta_covariance
from calibctl.core.extrinsics.se3 import rotation_from_rotvec
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.solve import residual_rms_px
from calibctl.core.intrinsics.validation import N_OCTANTS, N_RINGS, refit_pose, residual_breakdown

DEFAULT_ALPHA = 0.005  # whole-check false-fail probability under the noise model (target <= 1 %)
SHIFT_SHARE = (
    0.8  # of alpha for the delta model (what a focal or principal-point change does); the rest: regions
)
MIN_REGION_CORNERS = 30  # fewer corners in a region (fresh or stored) and it is reported, not tested
POSE_PARAMETERS = 6
MIN_CHECK_VIEWS = 10
"""Fewer fresh views and the check cannot judge (exit 2, nothing stored): the delta model's z-scores
assume the fresh estimate's covariance, which few real views understate (lens-model error is not iid
noise; the false fails were focal / cx / cy "moved" 3.3-6.6 sigma). Unchanged cameras failed on their
own photos (benchmarks/bench_check_few_views.py, opencv-left-right left + right): 14 of 24 checks at 1
view, 4/24 at 3, 5/24 at 5, 2/24 at 6, 4/80 at 7, 1/80 at 8, 0/80 at 9, 0/104 at 10, 0/80 at 12."""


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


def ratio_limit(dof_check: float, dof_reference: float, alpha: float, dispersion: float = 1.0) -> float:
    """Largest RMS ratio (check / reference) that is not a failure at one-sided level ``alpha``.

    ``dispersion`` (phi >= 1) inflates the iid variance of ln(ms_check / ms_ref) (module docstring).
    """
    z = NormalDist().inv_cdf(1.0 - alpha)
    return math.exp(z * 0.5 * math.sqrt(dispersion * (2.0 / dof_check + 2.0 / dof_reference)))


def view_dispersion(residuals_px: Sequence[np.ndarray]) -> float:
    """phi >= 1: cluster-robust variance of the pooled mean square (views as clusters) over its iid variance.

    Each view's sum of squares ss_v over n_v corners; pooled ms = sum ss / sum n. Under iid Gaussian noise
    var(ms) = 2 ms^2 / d; views with unequal noise make sum_v (ss_v - ms n_v)^2 / (sum n)^2 * V / (V - 1)
    larger. Below 1 (by chance) is clipped to 1: the test is never made stricter than the iid one.
    """
    ss = np.array([float(np.sum(np.asarray(r, np.float64) ** 2)) for r in residuals_px])
    n = np.array([len(r) for r in residuals_px], np.float64)
    n_views = len(ss)
    if n_views < 2 or ss.sum() <= 0:
        return 1.0
    ms = ss.sum() / n.sum()
    robust = float(np.sum((ss - ms * n) ** 2)) / n.sum() ** 2 * n_views / (n_views - 1)
    iid = 2.0 * ms**2 / _dof(n.sum(), n_views)
    return max(1.0, robust / iid)


def holm_levels(p_values: Sequence[float], alpha: float) -> list[float]:
    """Holm step-down: the level each test is judged at (reject while p <= level, in order of p).

    Tests after the first non-rejection keep that step's level, so "ratio <= limit" and "not rejected" agree.
    """
    m = len(p_values)
    order = sorted(range(m), key=lambda i: p_values[i])
    levels = [0.0] * m
    stopped: float | None = None
    for rank, i in enumerate(order):
        level = alpha / (m - rank) if stopped is None else stopped
        if stopped is None and p_values[i] > level:
            stopped = level
        levels[i] = level
    return levels


def recheck(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    reference: Reference,
    stored_sigma: dict[str, float],
    alpha: float = DEFAULT_ALPHA,
    model: str = DEFAULT_MODEL,
    stored_covariance: np.ndarray | None = None,
) -> RecheckResult:
    """Fit each fresh view's pose with the stored model and test its residuals against ``reference``.

    Args:
        object_points_per_view: V arrays (N_i, 3) float64 board frame, metres.
        image_points_per_view: V arrays (N_i, 2) float64 detected corners, px.
        camera_matrix: (3, 3) stored K, px. dist_coeffs: (n,) stored distortion, OpenCV order (fisheye:
        k1-k4). image_size: (W, H) px of both the calibration and the fresh views.
        reference: the calibration's held-out numbers. alpha: whole-check false-fail level, 80 % for
            the parameter tests, 20 % for the region tests.
        stored_sigma: the calibration's one-sigma of ``focal`` (relative), ``cx`` and ``cy`` (px); used
            when ``stored_covariance`` ((3, 3) of focal scale, cx, cy) is not given.
        model: the stored model's name (solve.MODELS): decides the projection, pinhole or fisheye.

    Raises:
        NumericalError: a view's pose could not be fitted (from validation.refit_pose).
    """
    K = np.asarray(camera_matrix, np.float64)
    D = np.asarray(dist_coeffs, np.float64).ravel()
    residuals, rvecs, tvecs, distances = [], [], [], []
    for obj, img in zip(object_points_per_view, image_points_per_view, strict=True):
        res, rvec, tvec = refit_pose(obj, img, K, D, model)
        residuals.append(res)
        rvecs.append(rvec)
        tvecs.append(tvec)
        R = rotation_from_rotvec(rvec)
        distances.append(
            float(np.linalg.norm(R @ np.asarray(obj, np.float64).reshape(-1, 3).mean(axis=0) + tvec))
        )
    regions = _region_tests(
        image_points_per_view,
        residuals,
        (float(K[0, 2]), float(K[1, 2])),
        image_size,
        reference,
        alpha * (1 - SHIFT_SHARE),
    )
    covariance = stored_delta_covariance(stored_sigma) if stored_covariance is None else stored_covariance
    shifts = intrinsic_shifts(
        object_points_per_view, K, D, rvecs, tvecs, residuals, covariance, alpha * SHIFT_SHARE, model
    )
    return RecheckResult(
        np.array([residual_rms_px(r) for r in residuals]),
        np.array(rvecs),
        np.array(tvecs),
        np.array(distances),
        tuple(regions),
        shifts,
        alpha,
    )


def _region_tests(
    image_points_per_view: Sequence[np.ndarray],
    residuals: list[np.ndarray],
    principal_point_px: tuple[float, float],
    image_size: tuple[int, int],
    reference: Reference,
    alpha: float,
) -> list[RegionVerdict]:
    """Overall, ring and octant variance-ratio tests, dispersion-corrected, Holm over the testable ones."""
    n_views = len(residuals)
    all_res = np.concatenate(residuals)
    edges = reference.ring_edges_px if reference.ring_edges_px is not None else np.zeros(N_RINGS - 1)
    parts = residual_breakdown(image_points_per_view, residuals, principal_point_px, image_size, edges)
    candidates = [("overall", residual_rms_px(all_res), reference.rms_px, len(all_res), reference.n_corners)]
    if reference.ring_edges_px is not None:
        candidates += [
            (
                f"ring {i + 1}",
                float(parts.ring_rms_px[i]),
                float(reference.ring_rms_px[i]),
                int(parts.ring_counts[i]),
                int(reference.ring_counts[i]),
            )
            for i in range(N_RINGS)
        ]
    candidates += [
        (
            f"octant {i}",
            float(parts.octant_rms_px[i]),
            float(reference.octant_rms_px[i]),
            int(parts.octant_counts[i]),
            int(reference.octant_counts[i]),
        )
        for i in range(N_OCTANTS)
    ]
    phi = view_dispersion(residuals)
    share_check = n_views / max(len(all_res), 1)  # pose parameters charged per corner
    share_ref = reference.n_views / max(reference.n_corners, 1)

    def scale(c: tuple[str, float, float, int, int]) -> float:  # one-sigma of ln(ratio)
        _, _, _, n, n_ref = c
        d_check, d_ref = _dof(n, round(n * share_check)), _dof(n_ref, round(n_ref * share_ref))
        return 0.5 * math.sqrt(phi * (2.0 / d_check + 2.0 / d_ref))

    testable = [c for c in candidates if _testable(c)]
    p_values = [1.0 - NormalDist().cdf(math.log(c[1] / c[2]) / scale(c)) for c in testable]
    levels = dict(zip([c[0] for c in testable], holm_levels(p_values, alpha), strict=True))
    regions = []
    for c in candidates:
        name, rms, ref_rms, n, _ = c
        level = levels.get(name, alpha / max(len(testable), 1))
        limit = math.exp(NormalDist().inv_cdf(1.0 - level) * scale(c))
        ratio = rms / ref_rms if name in levels else float("nan")
        regions.append(RegionVerdict(name, rms, ref_rms, ratio, limit, n, name in levels))
    return regions


def _testable(c: tuple[str, float, float, int, int]) -> bool:
    _, rms, ref_rms, n, n_ref = c
    return (
        n >= MIN_REGION_CORNERS
        and n_ref >= MIN_REGION_CORNERS
        and math.isfinite(rms)
        and math.isfinite(ref_rms)
        and ref_rms > 0
    )


def distance_ratio(board_distance_m: np.ndarray, reference_m: float) -> tuple[float, float]:
    """(median recovered / reference, relative spread of the recovered distances: (max - min) / median)."""
    d = np.asarray(board_distance_m, np.float64)
    median = float(np.median(d))
    return median / reference_m, float((d.max() - d.min()) / median)
