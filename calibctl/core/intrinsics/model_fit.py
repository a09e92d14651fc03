"""Is the lens model adequate? The fit RMS against the noise floor of the same corners.

The floor is the smaller of two estimates of what the corners deliver, each an upper bound of the noise:

- Lens-free (``detector_rms_px``): the image of a small patch of the board is smooth whatever the lens, so a
  quadratic map board (x, y) -> pixel (u, v) fitted to each 4 x 4 block of neighbouring corners leaves only
  the detector's noise and the patch's unmodelled curvature. Each block has 32 residuals and 12 parameters;
  the per-coordinate variance is the summed squares over the summed degrees of freedom, and the per-corner
  (2-D) RMS is sqrt(2) x that, the same definition as a solve's ``rms_px``. It over-reads where the field is
  strongly curved: 1.9x on a 185 deg circular render (0.547 px for 0.283 true), 5.9x with a 12 x 9 board held
  close to the same lens (1.681 px); a real fisheye set whose corners scatter 0.39 px read 3.7-4.1 px
  (reported by its user), where k1k2 fits passed the rule.
- Lens-model (``lens_floor_px``): the best of FLOOR_MODELS, the most flexible model of each lens family
  (fisheye, rational), by its own residuals with its degrees of freedom, rms * sqrt(2N / (2N - p)). It
  reads the noise wherever one of them describes the lens: 0.282-0.298 px on the renders above (truth 0.283).
  It over-reads only when no model fits, and then the lens-free estimate still bounds it.

The lens-free estimate is kept, not replaced, because on real photos the corners carry a small-scale
structure (print, board flatness, the detector's bias) that no lens model and no quadratic patch removes:
a cubic 4 x 4 patch reads 0.108 / 0.115 px on opencv-left-right left / right where every lens model fits
0.19 px, and 0.298 px on udacity-camcal where every model fits 0.80-0.85 px; judged against it, k1k2 on
those pinhole photos would be a "misfit" that no model fixes. The quadratic patch reads them at 0.194 /
0.221 / 0.486 px, and the floor (the smaller) stays there.

Measured (2026-11-27, 1032x778 renders of 15 views at 0.2 px per coordinate, seed 0, and the real sets after
the corner rule; table in docs/verdicts.md) -- fit RMS / floor (before: / patch alone): k1k2 on fisheye
renders 150 / 185 deg circular 5.8 / 8.7 (3.9 / 4.7), 120 deg full-frame 1.26 (1.21); fisheye on them
0.97-0.98 (0.48-0.93); a 12 x 9 board held close to a 185 deg lens: fisheye 0.98 (0.17). Real photos under
k1k2: opencv-left-right left 1.02 (1.01), right 0.99 (0.83), udacity-camcal 1.75 (1.75); acfr-lidar-camera (a
real 1920x1208 fisheye lens, ~80 deg across): fisheye 1.04, rational 0.99, k1k2 1.71 (k1k2 passes: 0.216 px).
The rule fails a calibration when the ratio exceeds MISFIT_RATIO and the excess exceeds MISFIT_MIN_PX (a
sub-pixel detector's slack). The lens-model estimate costs two solves: 0.22 s on acfr's 20 views; 0.36 / 0.44
s of CPU on the 19 / 86 views of a 20 / 96-image 1280x960 render (2026-11-27, 2-core VM). So it is read only
when it can matter (``noise_floor_px`` with the fit it judges): a fit of at most MISFIT_MIN_PX is no misfit
whatever the floor (the excess cannot exceed it), and then the floor stored is the lens-free one alone, which
is never below the full floor; the verdict is the same either way. The floor stored never exceeds the fit RMS
it judges (``_within_fit``): on a fisheye the patches over-read the noise (an accepted fisheye artifact
recorded 1.107 px for 0.10 px corner noise), and corners a model fits to R px carry at most R px of noise.
Measured on seeded fisheye corners at 0.2 px per coordinate (0.283 px per corner; tests/workflows/sessions.py
fisheye_capture, solved fisheye): 170 deg circular 0.422 -> 0.275 px, 150 deg full-frame 0.302 -> 0.281 px.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from calibctl.core.intrinsics.lens_checks import ERROR, Finding
from calibctl.core.lanes import Lanes, lanes_map
from calibctl.errors import NumericalError

if TYPE_CHECKING:
    from calibctl.core.intrinsics.solution import IntrinsicsSolution

BLOCK = 4  # corners per block side
MIN_BLOCK_CORNERS = 12
MISFIT_RATIO = 2.5
MISFIT_MIN_PX = 0.3
# Residuals that grow with radius: outer-quintile fit RMS over inner-quintile fit RMS. Measured 1.1-1.3 on
# the real sets and ~1.0 on pinhole renders (k1k2), 1.5-1.7 for k1k2 on fisheye renders.
RADIAL_GROWTH_RATIO = 2.0
# The models that solve fx and fy apart (core.intrinsics.solve MODELS); every other one ties fx to fy
# (CALIB_FIX_ASPECT_RATIO) and cannot fit non-square pixels either. Real 960x540 frames of a phone video
# (ynager/visual_odometry_pipeline, calibration_images/iphone6-*.png): fx/fy = 1.06 with the aspect free
# (RMS 0.26 px), k1k2 left 1.27 px (10.1x the detector) with cx 134 px, and the hint named only fisheye.
FREE_ASPECT_MODELS = ("fisheye", "opencv-default")
# The fisheye model is a fix only for a wide lens: diagonal field (the equidistant reading, module below) from
# this many degrees. A ~60 deg webcam reads ~85 deg; its misfit comes from corners no one lens explains
# (intrinsics that drift: focus, zoom), which a fisheye model fits no better.
WIDE_FIELD_DEG = 100.0


def diagonal_field_deg(camera_matrix: np.ndarray, image_size: tuple[int, int]) -> float:
    """The lens's diagonal field read as equidistant: 2 x the farthest image corner's normalised radius, deg.
    Exact for a fisheye, above a pinhole lens's 2 atan(r) (so a lens read narrow here is narrow)."""
    w, h = image_size
    fx, fy = float(camera_matrix[0][0]), float(camera_matrix[1][1])
    cx, cy = float(camera_matrix[0][2]), float(camera_matrix[1][2])
    u, v = np.array([-0.5, w - 0.5]), np.array([-0.5, h - 0.5])
    r = max(float(np.hypot((a - cx) / fx, (b - cy) / fy)) for a in u for b in v)
    return float(np.degrees(2 * r))


# The most flexible model of each lens family: the lens-model estimate of the noise floor (module docstring).
FLOOR_MODELS = ("fisheye", "rational")


def _grid_index(values: np.ndarray) -> np.ndarray:
    """Rank of each coordinate among the view's distinct ones (board rows/columns), tolerant of float
    noise."""
    distinct = np.unique(np.round(values, 9))
    return np.searchsorted(distinct, np.round(values, 9))


def detector_rms_px(
    object_points_per_view: Sequence[np.ndarray], image_points_per_view: Sequence[np.ndarray]
) -> float | None:
    """Per-corner RMS (px) of the detector, from local quadratic fits; None when no 4 x 4 block has enough
    corners.

    Args:
        object_points_per_view: V arrays (N_i, 3) float64 board frame (z = 0).
        image_points_per_view: V arrays (N_i, 2) float64 px.
    """
    ssr, dof = 0.0, 0
    for obj, img in zip(object_points_per_view, image_points_per_view, strict=True):
        obj = np.asarray(obj, np.float64).reshape(-1, 3)
        img = np.asarray(img, np.float64).reshape(-1, 2)
        col, row = _grid_index(obj[:, 0]) // BLOCK, _grid_index(obj[:, 1]) // BLOCK
        for key in set(zip(col.tolist(), row.tolist(), strict=True)):
            sel = (col == key[0]) & (row == key[1])
            if sel.sum() < MIN_BLOCK_CORNERS:
                continue
            x, y = obj[sel, 0], obj[sel, 1]
            scale = max(float(np.ptp(x)), float(np.ptp(y)), 1e-12)
            x, y = (x - x.mean()) / scale, (y - y.mean()) / scale
            A = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
            coef, *_ = np.linalg.lstsq(A, img[sel], rcond=None)
            ssr += float(np.sum((img[sel] - A @ coef) ** 2))
            dof += 2 * (int(sel.sum()) - A.shape[1])
    if dof == 0:
        return None
    return float(np.sqrt(2.0 * ssr / dof))


def lens_floor_px(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    models: Sequence[str] = FLOOR_MODELS,
    lanes: Lanes | None = None,
) -> tuple[float, str] | None:
    """(per-corner RMS px corrected for the fit's degrees of freedom, model) of the best of ``models`` on
    these corners; None when none can be solved. Shapes as in detector_rms_px; image_size (width, height) px.
    ``lanes``: where the models are solved at once (core.lanes); the answer does not depend on it."""
    # cv2 only here: `lint FILE` reads model_fit's rule without it
    from calibctl.core.intrinsics.solve import single_threaded_opencv, solve_intrinsics

    def solved(name: str) -> IntrinsicsSolution | None:
        try:
            return solve_intrinsics(
                list(object_points_per_view), list(image_points_per_view), image_size, name, uncertainty=False
            )
        except NumericalError:
            # too few views for it, or it diverged: the other family (or the patch) still reads the floor
            return None

    with single_threaded_opencv():
        solutions = lanes_map(lanes, solved, list(models))
    best: tuple[float, str] | None = None
    for sol in solutions:
        if sol is None:
            continue
        dof = sol.n_residuals - sol.n_parameters
        if dof <= 0:
            continue
        rms = float(sol.rms_px) * float(np.sqrt(sol.n_residuals / dof))
        if best is None or rms < best[0]:
            best = (rms, sol.model)
    return best


def noise_floor_px(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    fit_rms_px: float | None = None,
    lanes: Lanes | None = None,
) -> float | None:
    """The model-misfit rule's floor, px per corner: the smaller of detector_rms_px and lens_floor_px (module
    docstring); None when neither can be read. ``fit_rms_px``: the fit the floor will judge; when no floor can
    make it a misfit (``can_misfit``) and the lens-free estimate reads, that estimate alone is returned and
    the lens models are not solved. ``lanes``: as lens_floor_px."""
    reads = [detector_rms_px(object_points_per_view, image_points_per_view)]
    if reads[0] is not None and fit_rms_px is not None and not can_misfit(fit_rms_px):
        return _within_fit(reads[0], fit_rms_px)
    lens = lens_floor_px(object_points_per_view, image_points_per_view, image_size, lanes=lanes)
    reads.append(None if lens is None else lens[0])
    known = [r for r in reads if r is not None]
    return _within_fit(min(known), fit_rms_px) if known else None


def _within_fit(floor_px: float, fit_rms_px: float | None) -> float:
    """The floor, never above the fit it judges: corners a model fits to ``fit_rms_px`` carry at most that
    much noise, whatever a curved field makes the lens-free patches read (a floor above the fit cannot make it
    a misfit, so no verdict moves; only the stored noise figure becomes true)."""
    if fit_rms_px is None or not np.isfinite(fit_rms_px) or fit_rms_px <= 0:
        return floor_px
    return min(floor_px, float(fit_rms_px))


def can_misfit(fit_rms_px: float) -> bool:
    """False when ``misfit`` is False for every floor >= 0: the excess fit - floor never exceeds
    MISFIT_MIN_PX."""
    return not fit_rms_px <= MISFIT_MIN_PX  # NaN: may be anything, read the floor


def misfit(fit_rms_px: float, detector_px: float) -> bool:
    """True when the fit RMS is far above what the detector delivers (module docstring)."""
    return fit_rms_px > MISFIT_RATIO * detector_px and fit_rms_px - detector_px > MISFIT_MIN_PX


def check_model_misfit(
    fit_rms_px: float,
    detector_px: float | None,
    model: str,
    inner_fit_rms_px: float | None = None,
    outer_fit_rms_px: float | None = None,
    field_deg: float | None = None,
) -> Finding:
    """``model-misfit``: the fit RMS far above the detector's, or residuals that grow with radius.
    ``field_deg`` (diagonal_field_deg, when known) picks the fix: the fisheye model only for a lens of
    WIDE_FIELD_DEG or more."""
    fix = (
        "solve with --model fisheye (a wide or fisheye lens), or --model auto"
        if model != "fisheye"
        else "the fisheye model does not explain these corners either: check the board geometry and corner "
        "order"
    )
    if model != "fisheye" and field_deg is not None and field_deg < WIDE_FIELD_DEG:
        fix = (
            f"a lens of about {field_deg:.0f} deg diagonal is not wide: no richer model is the cure; the "
            "corners "
            "disagree with any one lens: check that focus, zoom and autofocus stayed fixed through the "
            "capture "
            "(see one-camera), that the board is flat and rigid, and the corner order; --model auto tries "
            "the "
            "richer models"
        )
    if model not in FREE_ASPECT_MODELS:
        fix += (
            f"; if the pixels are not square (frames resized in one axis, binning), {model} ties fx to fy "
            "and cannot fit them: --model opencv-default solves fx and fy apart"
        )
    if detector_px is None:
        return Finding("model-misfit", ERROR, True, "no detector noise recorded: model adequacy not checked")
    if misfit(fit_rms_px, detector_px):
        return Finding(
            "model-misfit",
            ERROR,
            False,
            f"model {model} leaves fit RMS {fit_rms_px:.3f} px where the corner detector delivers "
            f"{detector_px:.3f} px on this set ({fit_rms_px / detector_px:.1f}x, limit {MISFIT_RATIO:.1f}x): "
            "the model cannot describe this lens",
            fix,
        )
    if (
        inner_fit_rms_px
        and outer_fit_rms_px
        and outer_fit_rms_px > RADIAL_GROWTH_RATIO * inner_fit_rms_px
        and outer_fit_rms_px - inner_fit_rms_px > MISFIT_MIN_PX
    ):
        return Finding(
            "model-misfit",
            ERROR,
            False,
            f"residuals grow with radius under model {model}: outer-ring fit RMS {outer_fit_rms_px:.3f} px "
            "vs "
            f"inner {inner_fit_rms_px:.3f} px (limit {RADIAL_GROWTH_RATIO:.1f}x)",
            fix,
        )
    return Finding("model-misfit", ERROR, True, f"fit RMS {fit_rms_px:.3f} px, detector {detector_px:.3f} px")
