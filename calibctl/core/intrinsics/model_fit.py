"""Is the lens model adequate? The fit RMS against what the corner detector delivers on the same set.

Detector noise without a lens model: the image of a small patch of the board is smooth whatever the lens
(pinhole, fisheye, any distortion), so a quadratic map board (x, y) -> pixel (u, v) fitted to each 4 x 4
block of neighbouring corners leaves only the detector's noise (and a little unmodelled curvature). Each
block has 32 residuals and 12 parameters; the per-coordinate variance is the summed squares over the
summed degrees of freedom, and ``detector_rms_px`` is the per-corner (2-D) RMS, sqrt(2) x that, the same
definition as a solve's ``rms_px``. So a model that explains the corners has fit RMS ~ detector RMS, and
k1k2 on a fisheye does not.

Measured (2026-11-23; benchmarks/bench_model_misfit.py, BENCHMARKS section 12) -- fit RMS / detector RMS,
after the corner rule: pinhole renders (0.2 px noise, k1k2) 0.91-0.94; real photos under k1k2:
opencv-left-right left 1.01, right 0.83, udacity-camcal 1.75 (1.62 under rational); k1k2 on fisheye
renders 150-190 deg 4.2-6.2, on a 120 deg full-frame fisheye 1.39 (k1k2 is nearly adequate there); the
fisheye model on the same renders 0.58-0.95 (the 4x4 quadratic over-reads the noise of a strongly curved
circular fisheye by up to 1.7x, which errs on the side of passing). The rule fails a calibration when the
ratio exceeds MISFIT_RATIO and the excess exceeds MISFIT_MIN_PX (a sub-pixel detector's slack).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from calibctl.core.intrinsics.lens_checks import ERROR, Finding

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


def _grid_index(values: np.ndarray) -> np.ndarray:
    """Rank of each coordinate among the view's distinct ones (board rows/columns), tolerant of float noise."""
    distinct = np.unique(np.round(values, 9))
    return np.searchsorted(distinct, np.round(values, 9))


def detector_rms_px(object_points_per_view: Sequence[np.ndarray], image_points_per_view: Sequence[np.ndarray]) -> float | None:
    """Per-corner RMS (px) of the detector, from local quadratic fits; None when no 4 x 4 block has enough corners.

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


def misfit(fit_rms_px: float, detector_px: float) -> bool:
    """True when the fit RMS is far above what the detector delivers (module docstring)."""
    return fit_rms_px > MISFIT_RATIO * detector_px and fit_rms_px - detector_px > MISFIT_MIN_PX


def check_model_misfit(fit_rms_px: float, detector_px: float | None, model: str,
                       inner_fit_rms_px: float | None = None, outer_fit_rms_px: float | None = None) -> Finding:
    """``model-misfit``: the fit RMS far above the detector's, or residuals that grow with radius."""
    fix = ("solve with --model fisheye (a wide or fisheye lens), or --model auto" if model != "fisheye" else
           "the fisheye model does not explain these corners either: check the board geometry and corner order")
    if model not in FREE_ASPECT_MODELS:
        fix += (f"; if the pixels are not square (frames resized in one axis, binning), {model} ties fx to fy "
                "and cannot fit them: --model opencv-default solves fx and fy apart")
    if detector_px is None:
        return Finding("model-misfit", ERROR, True, "no detector noise recorded: model adequacy not checked")
    if misfit(fit_rms_px, detector_px):
        return Finding("model-misfit", ERROR, False,
                       f"model {model} leaves fit RMS {fit_rms_px:.3f} px where the corner detector delivers "
                       f"{detector_px:.3f} px on this set ({fit_rms_px / detector_px:.1f}x, limit {MISFIT_RATIO:.1f}x): "
                       "the model cannot describe this lens", fix)
    if inner_fit_rms_px and outer_fit_rms_px and outer_fit_rms_px > RADIAL_GROWTH_RATIO * inner_fit_rms_px \
            and outer_fit_rms_px - inner_fit_rms_px > MISFIT_MIN_PX:
        return Finding("model-misfit", ERROR, False,
                       f"residuals grow with radius under model {model}: outer-ring fit RMS {outer_fit_rms_px:.3f} px vs "
                       f"inner {inner_fit_rms_px:.3f} px (limit {RADIAL_GROWTH_RATIO:.1f}x)", fix)
    return Finding("model-misfit", ERROR, True, f"fit RMS {fit_rms_px:.3f} px, detector {detector_px:.3f} px")
