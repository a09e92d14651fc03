"""Numeric lint checks of a calibration that need only arrays (seed chapter 1, "three-line lint").

Every check returns a Finding: the rule id, the severity it carries when it fails, whether it
passed, a message with the numbers, and the fix. Thresholds are arguments (the defaults match
config.py's LintThresholds); the caller passes the configured values. Rules that need artifacts
(square-size provenance, schema, content hash) live with the artifacts, not here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

ERROR = "error"
WARNING = "warning"
RADIAL_GRID_STEPS = 4000  # samples of r_u between 0 and the farthest image corner's r_d
RADIAL_SEARCH_MAX_FACTOR = 10.0  # look for the corner's r_u up to this multiple of its r_d
POLAR_GRID = (200, 360)  # radii x angles for the 2-D Jacobian check


@dataclass(frozen=True)
class Finding:
    """One lint result. ``severity`` is what a failure means (error or warning)."""

    rule: str
    severity: str
    passed: bool
    message: str
    fix: str | None = None


def check_principal_point(
    camera_matrix: np.ndarray, image_size: tuple[int, int], max_frac: float = 0.1
) -> Finding:
    """|cx - W/2| < max_frac * W and |cy - H/2| < max_frac * H. camera_matrix: (3, 3) px."""
    w, h = image_size
    cx, cy = float(camera_matrix[0][2]), float(camera_matrix[1][2])
    dx, dy = abs(cx - w / 2), abs(cy - h / 2)
    ok = dx < max_frac * w and dy < max_frac * h
    msg = (
        f"principal point ({cx:.2f}, {cy:.2f}) is ({dx:.1f}, {dy:.1f}) px from the centre of the "
        f"declared {w}x{h} image; limit ({max_frac * w:.1f}, {max_frac * h:.1f}) px"
    )
    return Finding(
        "principal-point",
        ERROR,
        ok,
        msg,
        None
        if ok
        else "check that the image size is the resolution the corners were detected at "
        "(a K fitted at another resolution scales with it); if it is, recalibrate with tilted views",
    )


# sigma(fx) is linear in the corner scatter (seed chapter 1: 20.21 / 13.53 / 6.77 px at 0.3 / 0.2 / 0.1 px of
# noise), and the seed's production bar assumes sub-pixel corners at 0.2-0.3 px. A fit RMS above the seed's
# monitor alert level (0.5 px) means the scatter, not the poses, is what sigma(fx) is made of: more tilted
# views buy only sqrt(N), sharper corners on a flat board buy it linearly.
SCATTERED_FIT_RMS_PX = 0.5
SHARP_CORNERS_PX = "0.2-0.3"


def check_sigma_fx(
    sigma_fx_px: float | None,
    refused_reason: str | None = None,
    max_px: float = 2.0,
    fit_rms_px: float | None = None,
    detector_rms_px: float | None = None,
) -> Finding:
    """sigma(fx) must exist, be finite and stay under max_px (fx observable). ``fit_rms_px`` (the solve's
    per-corner RMS) and ``detector_rms_px`` (the corners' own scatter, ``model_fit.detector_rms_px``), when
    known, pick the fix: above SCATTERED_FIT_RMS_PX the corners, not the poses, are what to improve."""
    fix = "capture more views tilted 20-40 deg in at least three directions"
    if fit_rms_px is not None and math.isfinite(fit_rms_px) and fit_rms_px > SCATTERED_FIT_RMS_PX:
        alone = "" if detector_rms_px is None else f" (the corners alone scatter {detector_rms_px:.3f} px)"
        fix = (
            f"sigma(fx) grows linearly with the corner scatter: this fit leaves {fit_rms_px:.3f} px{alone}, "
            f"against {SHARP_CORNERS_PX} px for sharp corners on a flat board; first make the corners sharp "
            f"(focus, no motion blur, even light) and the board flat and rigid (a printed sheet bends), then "
            f"{fix}"
        )
    if sigma_fx_px is None:
        return Finding(
            "sigma-fx", ERROR, False, f"sigma(fx) is not available: {refused_reason or 'not recorded'}", fix
        )
    ok = math.isfinite(sigma_fx_px) and sigma_fx_px < max_px
    return Finding(
        "sigma-fx", ERROR, ok, f"sigma(fx) = {sigma_fx_px:.3f} px; limit {max_px:.3f} px", None if ok else fix
    )


# The ratio only counts when the held-out outer ring is also this many px worse than the fit's. Measured
# (2026-11-23, k-fold held-out of a model that fits): held-out minus fit outer-ring RMS 0.001-0.003 px on
# pinhole renders (0.2 px noise), 0.007 / 0.009 px on opencv-left-right left / right (k1k2); k1k2 on a
# 150 deg fisheye render: 1.2 px. 0.05 px is 5x the largest honest excess and far below a misfit's; the
# wide-angle case the plain ratio rejected (0.142 vs 0.125 px, excess 0.017 px) passes.
OUTER_RING_MIN_EXCESS_PX = 0.05


def check_outer_ring_holdout(
    holdout_outer_rms_px: float,
    fit_outer_rms_px: float,
    max_ratio: float = 1.1,
    min_excess_px: float = OUTER_RING_MIN_EXCESS_PX,
    model: str | None = None,
) -> Finding:
    """Held-out outer-ring RMS <= max_ratio * fit outer-ring RMS (no overfit distortion), unless the
    held-out excess is under min_excess_px (an absolute floor: tiny RMS values make any ratio noisy).
    ``model`` (the solve's model name, when known) picks the fix: never "fewer coefficients" to k1k2."""
    ratio = holdout_outer_rms_px / fit_outer_rms_px if fit_outer_rms_px > 0 else float("inf")
    excess = holdout_outer_rms_px - fit_outer_rms_px
    ok = math.isfinite(ratio) and (ratio <= max_ratio or excess < min_excess_px)
    msg = (
        f"held-out outer-ring RMS {holdout_outer_rms_px:.4f} px vs fit outer-ring RMS "
        f"{fit_outer_rms_px:.4f} px: ratio {ratio:.3f}, limit {max_ratio:.2f} "
        f"(counted only when {min_excess_px:.2f} px or more above the fit; here {excess:.4f} px)"
    )
    more_views = "capture more views with corners near the image edges and check that the board is flat"
    if model == "k1k2":
        fix = f"the model does not carry over to held-out outer-ring corners: {more_views}"
    elif model == "fisheye":
        fix = f"the fisheye model does not carry over to held-out outer-ring corners: {more_views}"
    elif model is not None:
        fix = (
            f"the model does not carry over to held-out outer-ring corners: {model} may over-fit them; solve "
            f"with fewer coefficients (--model k1k2 or auto), or {more_views}"
        )
    else:
        fix = (
            "the model does not carry over to held-out outer-ring corners: with more than k1 k2, solve "
            "with fewer coefficients (--model k1k2 or auto); with k1k2 already, " + more_views
        )
    return Finding("outer-ring-holdout", ERROR, ok, msg, None if ok else fix)


def check_image_size(image_size: tuple[int, int] | None, camera_matrix: np.ndarray) -> Finding:
    """The image size is recorded, positive, and the principal point lies inside it."""
    if image_size is None:
        return Finding(
            "image-size",
            ERROR,
            False,
            "no image size is recorded with the calibration",
            "record the resolution the corners were detected at",
        )
    w, h = image_size
    if not (int(w) == w and int(h) == h and w > 0 and h > 0):
        return Finding(
            "image-size",
            ERROR,
            False,
            f"image size {image_size} is not two positive integers",
            "record the resolution the corners were detected at",
        )
    cx, cy = float(camera_matrix[0][2]), float(camera_matrix[1][2])
    ok = 0 < cx < w and 0 < cy < h
    return Finding(
        "image-size",
        ERROR,
        ok,
        f"principal point ({cx:.2f}, {cy:.2f}) {'lies' if ok else 'does not lie'} inside the "
        f"recorded {w}x{h} image",
        None if ok else "the recorded image size does not belong to this K; record the detection resolution",
    )


def check_finite(values: Mapping[str, object]) -> Finding:
    """Every named number or array is finite. values: name -> float or array."""
    bad = [name for name, v in values.items() if not np.isfinite(np.asarray(v, dtype=np.float64)).all()]
    return Finding(
        "finite",
        ERROR,
        not bad,
        f"non-finite values in: {', '.join(bad)}"
        if bad
        else f"all {len(values)} recorded quantities are finite",
        "re-solve; a calibration with NaN or infinity cannot be used" if bad else None,
    )


def check_aspect_ratio(camera_matrix: np.ndarray, max_frac: float = 0.01) -> Finding:
    """|fx/fy - 1| <= max_frac (warning: square pixels expected on a modern sensor)."""
    fx, fy = float(camera_matrix[0][0]), float(camera_matrix[1][1])
    dev = abs(fx / fy - 1.0)
    ok = dev <= max_frac
    return Finding(
        "aspect-ratio",
        WARNING,
        ok,
        f"fx/fy = {fx / fy:.5f} ({100 * dev:.2f} % from 1; limit {100 * max_frac:.2f} %)",
        None
        if ok
        else "unusual for square pixels: check for one-axis binning or an "
        "anamorphic lens, or a poorly tilted capture",
    )


def _padded(dist_coeffs: np.ndarray) -> np.ndarray:
    d = np.zeros(12)
    src = np.asarray(dist_coeffs, dtype=np.float64).ravel()
    if src.size > 12 and np.any(src[12:] != 0):
        raise ValueError("tilted-sensor distortion terms (tau_x, tau_y) are not supported by this check")
    d[: min(12, src.size)] = src[:12]
    return d


def distort_normalised(x: np.ndarray, y: np.ndarray, dist_coeffs: np.ndarray) -> tuple[np.ndarray, ...]:
    """OpenCV's distortion (k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4) of normalised coordinates.

    Returns (x_d, y_d, denominator) arrays of the input shape; denominator is 1 + k4 r^2 + ...
    """
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = _padded(dist_coeffs)
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    g = num / den
    xd = x * g + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r2 * r2
    yd = y * g + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r2 * r2
    return xd, yd, den


def _radial(r: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(r_d, denominator) of ``distort_normalised`` along y = 0 with p1 = p2 = s1..s4 = 0: the same
    arithmetic without the terms that are exactly zero there, so the same bits at half the cost."""
    k1, k2, _, _, k3, k4, k5, k6 = d[:8]
    r2 = r * r
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    return r * ((1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / den), den


CIRCLE_SAMPLES = 720  # points on the image circle when the farthest imaged point is looked for


# Fold-over is judged where the calibration is used: the observed corners' region grown by this share of its
# radius (a model is extrapolated a little beyond the last corner in use), never beyond the image (or circle).
OBSERVED_MARGIN = 0.1


def observed_region_px(corners_px: Sequence[np.ndarray]) -> np.ndarray | None:
    """(K, 2) float64 vertices of the convex hull of every corner (V arrays (N_i, 2) px), or None without
    3."""
    pts = (
        np.concatenate([np.asarray(c, np.float64).reshape(-1, 2) for c in corners_px]) if corners_px else None
    )
    if pts is None or len(pts) < 3:
        return None
    import cv2  # here, not at the top: lint of a file (no solve) must not pay OpenCV's import

    return np.asarray(cv2.convexHull(pts.astype(np.float32)), np.float64).reshape(-1, 2)


def _farthest_corner_rd(
    camera_matrix: np.ndarray,
    image_size: tuple[int, int],
    image_circle: tuple[float, float, float] | None = None,
    observed_px: np.ndarray | None = None,
    required_px: np.ndarray | None = None,
) -> tuple[float, str]:
    """Normalised distorted radius out to which a model is judged, and its words: the image point farthest
    from the principal point (an image corner, or with ``image_circle`` (cx, cy, r px) the farthest point of
    the image inside the circle); with ``observed_px`` ((K, 2) px, the observed corners' hull) the farthest
    observed corner grown by OBSERVED_MARGIN when that is nearer (the model is not used beyond it), or the
    farthest vertex of ``required_px`` ((K, 2) px, the station's declared region) when that reaches farther:
    the union of both."""
    w, h = image_size
    fx, fy = float(camera_matrix[0][0]), float(camera_matrix[1][1])
    cx, cy = float(camera_matrix[0][2]), float(camera_matrix[1][2])
    u, v = np.meshgrid(np.array([-0.5, w - 0.5]), np.array([-0.5, h - 0.5]))
    u, v = u.ravel(), v.ravel()
    if image_circle is not None:
        ccx, ccy, r = image_circle
        keep = np.hypot(u - ccx, v - ccy) <= r
        a = np.linspace(0.0, 2 * np.pi, CIRCLE_SAMPLES, endpoint=False)
        cu, cv = np.clip(ccx + r * np.cos(a), -0.5, w - 0.5), np.clip(ccy + r * np.sin(a), -0.5, h - 0.5)
        u, v = np.concatenate([u[keep], cu]), np.concatenate([v[keep], cv])
    rd = float(np.hypot((u - cx) / fx, (v - cy) / fy).max())
    edge = "farthest image corner" if image_circle is None else "farthest image point inside the image circle"
    if observed_px is not None and len(observed_px):
        obs = np.asarray(observed_px, np.float64).reshape(-1, 2)
        rd_obs = float(np.hypot((obs[:, 0] - cx) / fx, (obs[:, 1] - cy) / fy).max()) * (1 + OBSERVED_MARGIN)
        req = np.asarray(required_px if required_px is not None else np.zeros((0, 2)), np.float64).reshape(
            -1, 2
        )
        rd_req = float(np.hypot((req[:, 0] - cx) / fx, (req[:, 1] - cy) / fy).max()) if len(req) else 0.0
        if max(rd_obs, rd_req) < rd:
            if rd_req > rd_obs:
                return rd_req, "station region (the farthest point of gates.projection_region)"
            return rd_obs, f"observed region (the farthest corner + {OBSERVED_MARGIN:.0%})"
    return rd, edge


def _is_region(edge: str) -> bool:
    """Whether the judged radius is a region's (observed or station-declared), not the image's edge."""
    return edge.startswith(("observed", "station"))


def _inside(edge: str) -> str:
    return edge.split(" (")[0] if _is_region(edge) else "image"


def check_distortion_foldover(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    image_circle: tuple[float, float, float] | None = None,
    model: str | None = None,
    observed_px: np.ndarray | None = None,
    required_px: np.ndarray | None = None,
) -> Finding:
    """The distortion is one-to-one out to the farthest image corner (with ``image_circle`` (cx, cy, r)
    px: out to the farthest point of the image inside the circle, where the lens forms an image; with
    ``observed_px`` (the observed corners' hull, px): no farther than the observed region grown by
    OBSERVED_MARGIN, where the calibration is used, alike for every model; with ``required_px`` too, the
    station's declared region where it reaches farther: a robot that looks there needs the model one-to-one
    there).

    Radial part: r_d(r_u) = r_u * (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
    must increase strictly, with a positive denominator, on a fine grid from 0 until it reaches
    the distorted normalised radius of the farthest image corner (it must reach it at all).
    Full model incl. tangential and thin-prism terms: the Jacobian determinant of
    (x, y) -> (x_d, y_d) must be positive on a polar grid over that same disc of r_u.
    ``model`` (the solve's model name, when known) picks the fix: never "fewer coefficients" to k1k2.
    """
    rule, fix = (
        "distortion-foldover",
        (
            "the distortion polynomial turns back inside the image: "
            "re-solve with fewer coefficients (--model k1k2) or with "
            "corners captured out to the image corners"
        ),
    )
    if model == "k1k2":
        fix = (
            "the distortion polynomial turns back inside the image: capture corners out to the image corners "
            "(it is extrapolated beyond the last one), or --model fisheye for a wide or fisheye lens"
        )
    rd_corner, edge = _farthest_corner_rd(camera_matrix, image_size, image_circle, observed_px, required_px)
    r_max = RADIAL_SEARCH_MAX_FACTOR * rd_corner
    steps = int(RADIAL_GRID_STEPS * RADIAL_SEARCH_MAX_FACTOR)
    radial_only = _padded(dist_coeffs)
    radial_only[[2, 3, 8, 9, 10, 11]] = 0.0  # p1 p2 s1..s4
    is_radial = bool(np.array_equal(radial_only, _padded(dist_coeffs)))
    # The corner is usually reached within 2x its r_d: search that prefix of the grid first (the
    # samples np.linspace(0, r_max, steps + 1) would give), the whole grid only when it is not reached.
    r = np.arange(2 * RADIAL_GRID_STEPS + 1) * (r_max / steps)
    rd, den = _radial(r, radial_only)
    reach_idx = np.flatnonzero(rd >= rd_corner)
    if not reach_idx.size:
        r = np.linspace(0.0, r_max, steps + 1)
        rd, den = _radial(r, radial_only)
        reach_idx = np.flatnonzero(rd >= rd_corner)
    stop = int(reach_idx[0]) if reach_idx.size else len(r) - 1
    seg_rd, seg_den = rd[: stop + 1], den[: stop + 1]
    falling = np.flatnonzero((np.diff(seg_rd) <= 0) | (seg_den[1:] <= 0))
    if falling.size or not reach_idx.size:
        if falling.size:
            i = int(falling[0])
            where = f"stops increasing at r_u = {r[i]:.4f} (r_d = {rd[i]:.4f})"
        else:
            i = int(np.argmax(rd))
            where = f"never exceeds r_d = {rd[i]:.4f} (at r_u = {r[i]:.4f}, searched to r_u = {r_max:.3f})"
        return Finding(
            rule,
            ERROR,
            False,
            f"radial distortion r_d(r_u) {where}, but the {edge} is at "
            f"r_d = {rd_corner:.4f} (normalised): the model folds over inside the {_inside(edge)}",
            fix,
        )
    r_reach = float(r[stop])
    radii = np.linspace(0.0, r_reach, POLAR_GRID[0])[1:]
    angles = np.linspace(0.0, 2 * np.pi, POLAR_GRID[1], endpoint=False)
    if is_radial:  # a radial map's Jacobian does not depend on the angle: one ray of the grid is enough
        angles = angles[:1]
    rr, aa = np.meshgrid(radii, angles)
    x, y = rr * np.cos(aa), rr * np.sin(aa)
    step = 1e-6
    # the four central-difference stencils in one call: the same element-wise arithmetic, a quarter of
    # numpy's per-call overhead
    xs, ys, _ = distort_normalised(
        np.stack([x + step, x - step, x, x]), np.stack([y, y, y + step, y - step]), dist_coeffs
    )
    (xp, xm, xq, xn), (yp, ym, yq, yn) = xs, ys
    det = ((xp - xm) * (yq - yn) - (xq - xn) * (yp - ym)) / (4 * step * step)
    worst = np.unravel_index(int(np.argmin(det)), det.shape)
    if not det[worst] > 0:
        return Finding(
            rule,
            ERROR,
            False,
            f"the distortion (incl. tangential terms) folds over: Jacobian determinant "
            f"{det[worst]:.3g} at r_u = {rr[worst]:.4f}, angle {np.rad2deg(aa[worst]):.0f} deg, "
            f"inside the disc reaching the {edge} (r_u = {r_reach:.4f})",
            fix,
        )
    return Finding(
        rule,
        ERROR,
        True,
        f"distortion is one-to-one out to the {edge} (r_d = {rd_corner:.4f}, "
        f"r_u = {r_reach:.4f}); smallest Jacobian determinant {det[worst]:.3f}",
    )


def check_equidistant_foldover(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    image_circle: tuple[float, float, float] | None = None,
    observed_px: np.ndarray | None = None,
    required_px: np.ndarray | None = None,
) -> Finding:
    """Equidistant (fisheye, k1..k4): theta_d(theta) = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8)
    must increase from theta = 0 until it reaches the farthest image corner's normalised radius.

    theta is the angle off the optical axis (radians), searched up to pi. A model that never reaches
    the corner's radius describes a circular fisheye whose image corners are outside the image circle,
    where the lens forms no image: it is then checked out to 90 deg off-axis (a 180 deg field).
    With ``image_circle`` (cx, cy, r) px the farthest point of the image inside the circle replaces the
    farthest image corner, and the model must reach it (the lens images the circle's edge). With
    ``observed_px`` the observed region grown by OBSERVED_MARGIN, when nearer, replaces both (and the model
    must reach it: corners were imaged there): a fold beyond every observed corner is not judged.
    ``required_px`` (the station's declared region) joins the observed one, as for check_distortion_foldover.
    """
    rule = "distortion-foldover"
    fix = "the fisheye polynomial turns back inside the image: re-solve with corners out to the image edge"
    k1, k2, k3, k4 = (list(np.asarray(dist_coeffs, dtype=np.float64).ravel()) + [0.0] * 4)[:4]
    rd_corner, edge = _farthest_corner_rd(camera_matrix, image_size, image_circle, observed_px, required_px)
    must_reach = image_circle is not None or _is_region(edge)
    theta = np.linspace(0.0, math.pi, RADIAL_GRID_STEPS + 1)
    t2 = theta * theta
    theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    reach = np.flatnonzero(theta_d >= rd_corner)
    # without a circle, a model that never reaches the corner is a circular fisheye: checked to 90 deg; the
    # edge of a known circle is imaged, so the model must reach it
    limit = len(theta) - 1 if must_reach else int(np.searchsorted(theta, math.pi / 2))
    stop = int(reach[0]) if reach.size else limit
    falling = np.flatnonzero(np.diff(theta_d[: stop + 1]) <= 0)
    if not falling.size and not reach.size and must_reach:
        what = edge if _is_region(edge) else "circle's edge"
        return Finding(
            rule,
            ERROR,
            False,
            f"fisheye theta_d(theta) never reaches the {edge} (theta_d = {rd_corner:.4f}; at most "
            f"{theta_d.max():.4f} out to 180 deg off-axis): the model cannot image the {what}",
            fix,
        )
    if falling.size:
        i = int(falling[0])
        return Finding(
            rule,
            ERROR,
            False,
            f"fisheye theta_d(theta) stops increasing at {math.degrees(theta[i]):.1f} deg off-axis "
            f"(theta_d = {theta_d[i]:.4f}) before reaching the {edge} "
            f"(theta_d = {rd_corner:.4f}): the model folds over inside the {_inside(edge)}",
            fix,
        )
    return Finding(
        rule,
        ERROR,
        True,
        f"fisheye theta_d(theta) increases out to {math.degrees(theta[stop]):.1f} deg off-axis "
        f"({edge} at theta_d = {rd_corner:.4f})",
    )
