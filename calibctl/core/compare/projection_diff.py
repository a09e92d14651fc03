"""The projection difference of two lenses over the imager, its expected spread, and the test.

What is compared (mrcal's show-projection-diff): a grid of pixels q over A's imager is unprojected with
A's model to rays (points at ``range_m`` along them), projected with B's model, and d(q) = q_B - q is
the difference in px. "raw" compares the two camera frames as stored (what a robot whose extrinsics
were not re-solved sees); "fit" first applies the rigid motion that best aligns B to A in the least
squares sense (a rotation at infinite range, rotation and translation at a finite one, as mrcal), which
is what a re-solved extrinsic would absorb, so it shows the change of the lens's shape.

Expected spread: linearised, d = J_B dtheta_B - M J_A dtheta_A (J = dq/dtheta at the ray held fixed,
M = B's image map of A's: dq_B/dp (dq_A/dp)^+, the identity when A = B). With independent estimates,
Cov(d) = J_B S_B J_B^T + M J_A S_A J_A^T M^T; two versions of one lens model share J (to first order at
A = B), so Cov(d) = J (S_A + S_B) J^T. After the fit, d_fit = P d with P the least-squares projection
off the motion's Jacobian columns, so Cov(d_fit) = P Cov(d) P^T.

The test: stacked over the grid, d is (to first order) G z with z ~ N(0, I) and G = J L (L L^T = S),
so T = d^T Cov(d)^+ d ~ chi2(rank G) when the two calibrations are of one unchanged camera. It is the
most powerful test of "one parameter vector" against "any other" and it is exact: no multiple-testing
correction across the correlated samples is needed. Equivalently (Scheffe), the lenses are "different"
when some weighted combination of the samples' differences leaves its sqrt(chi2 quantile)-sigma band.
Raw and fit are tested at ALPHA / 2 each (Bonferroni), so an unchanged camera is flagged with at most
ALPHA probability, to the extent the stored covariances are honest. A difference that no parameter
noise of either model can produce (different lens models, or a difference outside the span of G) is
``unexplained``; it is flagged when it exceeds UNEXPLAINED_LIMIT_PX anywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibctl.core.compare.chi2 import chi2_quantile, chi2_sf
from calibctl.core.compare.lens import Lens, Projection, project, sample_pixels, unproject

ALPHA = 0.01  # false-flag probability of an unchanged camera (raw and fit at ALPHA / 2 each)
UNEXPLAINED_LIMIT_PX = 0.1  # a difference outside both covariances' span, beyond what a detector resolves
SPREAD_FLOOR_PX = 1e-3  # directions whose one-sigma pattern is below this RMS px are not tested (numerics)
FOLD_TOLERANCE_RAD = 1e-6  # a pixel B maps back to another ray than the one projected is past B's fold-over
# of the image size past each edge: still the region a lens maps (a 0.3 % focal change moves a corner sample
# a pixel or two outward)
IMAGE_MARGIN = 0.1
DEFAULT_GRID = (40, 30)
PERCENTILES = (50, 90, 99)
_FIT_ITERATIONS = 20


@dataclass(frozen=True)
class ChiSquare:
    """T = d^T Cov(d)^+ d against chi2(dof); unexplained: the part of d outside Cov's span, px."""

    statistic: float
    dof: int
    p_value: float
    threshold: float
    significant: bool
    unexplained_max_px: float
    unexplained_rms_px: float


@dataclass(frozen=True)
class DiffField:
    """One difference field over the valid samples.

    diff_px: (M, 2) q_B - q, px. sigma_px: (M,) expected one-sigma in the sample's worst direction (None
    without both covariances). z: (M,) per-sample Mahalanobis length sqrt(d^T C^-1 d) of its 2x2 C.
    percentiles_px: |d| at 50/90/99 % and max. test: the chi-square test (None without covariances).
    """

    diff_px: np.ndarray
    sigma_px: np.ndarray | None
    z: np.ndarray | None
    percentiles_px: dict[str, float]
    test: ChiSquare | None


@dataclass(frozen=True)
class ProjectionDiff:
    """The comparison of lens B against lens A.

    pixels_px: (M, 2) valid grid samples over A's imager; grid: (cols, rows); dropped: samples outside
    either model. raw / fit: the two fields. rvec_fit: (3,) rad, tvec_fit_m: (3,) the fitted motion of
    B's frame (zeros at infinite range). range_m: inf for rays. significant: the verdict (None without
    both covariances); reasons: why, in words.
    """

    pixels_px: np.ndarray
    grid: tuple[int, int]
    dropped: int
    range_m: float
    raw: DiffField
    fit: DiffField
    rvec_fit: np.ndarray
    tvec_fit_m: np.ndarray
    significant: bool | None
    reasons: tuple[str, ...]

    @property
    def rotation_fit_deg(self) -> float:
        return float(np.rad2deg(np.linalg.norm(self.rvec_fit)))


def _percentiles(d: np.ndarray) -> dict[str, float]:
    mag = np.linalg.norm(d, axis=1)
    out = {f"p{p}": float(np.percentile(mag, p)) for p in PERCENTILES}
    out["max"] = float(mag.max())
    return out


def _chi_square(d: np.ndarray, G: np.ndarray, alpha: float) -> ChiSquare:
    """d (M, 2), G (M, 2, n): T = |G^+ d|^2 over the directions whose spread clears SPREAD_FLOOR_PX."""
    m = len(d)
    flat_d, flat_G = d.reshape(-1), G.reshape(2 * m, -1)
    U, s, _ = np.linalg.svd(flat_G, full_matrices=False)
    keep = s > max(s[0] * 1e-9, SPREAD_FLOOR_PX * math.sqrt(m)) if len(s) else np.zeros(0, bool)
    Uk = U[:, keep]
    c = Uk.T @ flat_d
    stat = float(np.sum((c / s[keep]) ** 2))
    dof = int(keep.sum())
    rest = (flat_d - Uk @ c).reshape(m, 2)
    rest_mag = np.linalg.norm(rest, axis=1)
    if dof == 0:
        return ChiSquare(
            stat, 0, 1.0, 0.0, False, float(rest_mag.max()), float(np.sqrt(np.mean(rest_mag**2)))
        )
    p = chi2_sf(stat, dof)
    return ChiSquare(
        stat,
        dof,
        p,
        chi2_quantile(1.0 - alpha, dof),
        p < alpha,
        float(rest_mag.max()),
        float(np.sqrt(np.mean(rest_mag**2))),
    )


def _per_sample(d: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Worst-direction sigma (M,) and Mahalanobis length (M,) of each sample's 2x2 covariance G G^T."""
    C = np.einsum("mik,mjk->mij", G, G)
    w, V = np.linalg.eigh(C)
    sigma = np.sqrt(np.clip(w[:, -1], 0.0, None))
    floor = (SPREAD_FLOOR_PX**2) + 1e-12 * w[:, -1:]
    coords = np.einsum("mji,mj->mi", V, d)
    z = np.sqrt(np.sum(coords**2 / np.maximum(w, floor), axis=1))
    return sigma, z


def _fit_motion(
    b: Lens, points: np.ndarray, target_px: np.ndarray, translate: bool
) -> tuple[np.ndarray, Projection]:
    """Gauss-Newton on B's pose (rvec, and tvec when ``translate``) minimising |q_B - target|^2."""
    x = np.zeros(6)
    cols = slice(0, 6) if translate else slice(0, 3)
    pb = project(b, points)
    for _ in range(_FIT_ITERATIONS):
        J = pb.J_pose[:, :, cols].reshape(-1, cols.stop)
        r = (pb.q_px - target_px).reshape(-1)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        x[cols] += step
        pb = project(b, points, x[:3], x[3:])
        if np.linalg.norm(step) < 1e-12:
            break
    return x, pb


def _sensitivities(a: Lens, b: Lens, pa: Projection, pb: Projection) -> np.ndarray | None:
    """G (M, 2, n) with Cov(d) = G G^T per the module docstring; None unless both lenses carry a
    covariance."""
    if a.covariance is None or b.covariance is None or pa.J_theta is None or pb.J_theta is None:
        return None
    if tuple(a.parameters) == tuple(b.parameters) and a.fisheye == b.fisheye:
        return np.einsum("mip,pk->mik", pb.J_theta, _root(a.covariance + b.covariance))
    Jp = pa.J_point
    pinv = np.transpose(Jp, (0, 2, 1)) @ np.linalg.inv(Jp @ np.transpose(Jp, (0, 2, 1)))
    M = pb.J_point @ pinv
    Ga = -np.einsum("mij,mjp,pk->mik", M, pa.J_theta, _root(a.covariance))
    Gb = np.einsum("mip,pk->mik", pb.J_theta, _root(b.covariance))
    return np.concatenate([Gb, Ga], axis=2)


def _root(cov: np.ndarray) -> np.ndarray:
    """L with L L^T = cov for a symmetric positive semi-definite cov (eigen square root)."""
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    return V * np.sqrt(np.clip(w, 0.0, None))


def _field(d: np.ndarray, G: np.ndarray | None, alpha: float) -> DiffField:
    if G is None:
        return DiffField(d, None, None, _percentiles(d), None)
    sigma, z = _per_sample(d, G)
    return DiffField(d, sigma, z, _percentiles(d), _chi_square(d, G, alpha))


def projection_diff(
    a: Lens, b: Lens, grid: tuple[int, int] = DEFAULT_GRID, range_m: float = math.inf, alpha: float = ALPHA
) -> ProjectionDiff:
    """Compare lens B against lens A (same pixel frame: scale one first with ``Lens.scaled``).

    Args: grid (cols, rows) samples over A's imager; range_m: distance of the compared points along
    A's rays, metres (inf: rays, the fit is a rotation); alpha: total false-flag probability.

    Raises:
        ValueError: the image sizes differ, or fewer than 10 samples are inside both models.
    """
    if tuple(a.image_size) != tuple(b.image_size):
        raise ValueError(f"image sizes differ: {a.image_size} and {b.image_size}")
    pixels = sample_pixels(a.image_size, grid)
    rays, ok = unproject(a, pixels)
    points = rays * (range_m if math.isfinite(range_m) else 1.0)
    pb = project(b, points)
    back, ok_b = unproject(b, np.where(np.isfinite(pb.q_px), pb.q_px, 0.0))
    same_ray = np.einsum("ij,ij->i", back, rays) > math.cos(
        FOLD_TOLERANCE_RAD
    )  # B's polynomial has not folded over
    keep = ok & pb.valid & ok_b & same_ray & _in_image(pb.q_px, b.image_size)
    if keep.sum() < 10:
        raise ValueError(f"only {int(keep.sum())} of {len(pixels)} samples are inside both lens models")
    pixels, points = pixels[keep], points[keep]
    pa, pb = project(a, points), project(b, points)
    d_raw = pb.q_px - pixels
    x, pf = _fit_motion(b, points, pixels, translate=math.isfinite(range_m))
    d_fit = pf.q_px - pixels
    G = _sensitivities(a, b, pa, pb)
    G_fit = None
    if G is not None:  # P = I - Jn Jn^+ acting on the stacked samples
        n_cols = 6 if math.isfinite(range_m) else 3
        Jn = pf.J_pose[:, :, :n_cols].reshape(-1, n_cols)
        flat = G.reshape(-1, G.shape[2])
        flat = flat - Jn @ np.linalg.lstsq(Jn, flat, rcond=None)[0]
        G_fit = flat.reshape(G.shape)
    raw, fit = _field(d_raw, G, alpha / 2), _field(d_fit, G_fit, alpha / 2)
    significant, reasons = _verdict(raw, fit)
    return ProjectionDiff(
        pixels, grid, int((~keep).sum()), range_m, raw, fit, x[:3], x[3:], significant, reasons
    )


def _in_image(q_px: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """(M,) the pixels lie on the image, or within ``IMAGE_MARGIN`` of its size past an edge: the region a
    lens maps. A wide fisheye's rays sent through a pinhole model land thousands of px off the image, where
    neither calibration saw a corner (13 million px differences "expected" to 1.9 million px)."""
    size = np.asarray(image_size, dtype=np.float64)
    lo, hi = -0.5 - IMAGE_MARGIN * size, size - 0.5 + IMAGE_MARGIN * size
    return np.all(np.isfinite(q_px) & (q_px >= lo) & (q_px <= hi), axis=1)


def _verdict(raw: DiffField, fit: DiffField) -> tuple[bool | None, tuple[str, ...]]:
    if raw.test is None or fit.test is None:
        return None, ("no verdict: a calibration stores no covariance, so the expected spread is unknown",)
    reasons = []
    for name, f in (("as stored", raw), ("after the fitted rotation", fit)):
        t = f.test
        assert t is not None
        if t.significant:
            reasons.append(
                f"{name}: chi2 {t.statistic:.1f} > {t.threshold:.1f} ({t.dof} dof, p = {t.p_value:.2g})"
            )
    unexplained = raw.test.unexplained_max_px
    if unexplained > UNEXPLAINED_LIMIT_PX:
        reasons.append(
            f"{unexplained:.2f} px of the difference is outside what either calibration's noise can "
            f"produce (limit {UNEXPLAINED_LIMIT_PX} px): the lens models disagree in shape"
        )
    if reasons:
        return True, tuple(reasons)
    return False, (
        f"within noise: chi2 {raw.test.statistic:.1f} <= {raw.test.threshold:.1f} as stored, "
        f"{fit.test.statistic:.1f} <= {fit.test.threshold:.1f} after the fitted rotation",
    )
