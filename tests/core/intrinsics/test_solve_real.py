"""The solve on real photographs against the reference numbers in the datasets' DATASET.md.

Detection is a small local helper (findChessboardCorners ADAPTIVE_THRESH|NORMALIZE_IMAGE, then
cornerSubPix 11x11), the recipe the reference numbers were made with; calibctl's own detector is
tested elsewhere.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_geometry import chessboard_object_points
from calibctl.core.intrinsics.outliers import (
    corner_outlier_threshold_px,
    find_corner_outliers,
    flag_outliers,
    solve_rejecting_corners,
)
from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.intrinsics.validation import refit_pose_residuals
from tests.datasets import LEFT_RIGHT, UDACITY, needs_datasets

PATTERN = (9, 6)
REFERENCE_TOL_PX = 0.01  # the bar for reproducing plain OpenCV

pytestmark = needs_datasets


def detect(path: Path) -> tuple[np.ndarray | None, tuple[int, int]]:
    """(54, 2) float64 sub-pixel corners or None, and the image's (width, height)."""
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    ok, corners = cv2.findChessboardCorners(
        gray, PATTERN, cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    )
    size = (gray.shape[1], gray.shape[0])
    if not ok:
        return None, size
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria)
    return corners.reshape(-1, 2).astype(np.float64), size


def detect_all(paths: list[Path]) -> list[tuple[str, np.ndarray, tuple[int, int]]]:
    found = []
    for p in paths:
        corners, size = detect(p)
        if corners is not None:
            found.append((p.name, corners, size))
    return found


def _natural(p: Path) -> int:
    return int("".join(ch for ch in p.stem if ch.isdigit()))


@pytest.fixture(scope="module")
def left_views():
    views = detect_all(sorted(LEFT_RIGHT.glob("left*.jpg"), key=_natural))
    assert len(views) == 13
    return views


@pytest.fixture(scope="module")
def udacity_views():
    views = detect_all(sorted(UDACITY.glob("calibration*.jpg"), key=_natural))
    assert len(views) == 17  # DATASET.md: no detection in calibration1, 4, 5
    return views


def model_points() -> np.ndarray:
    return chessboard_object_points(*PATTERN, square_size_m=1.0)  # reference used square size 1.0


def test_left_images_reproduce_the_plain_opencv_reference(left_views):
    obj = [model_points()] * len(left_views)
    sol = solve_intrinsics(obj, [c for _, c, _ in left_views], (640, 480), "opencv-default")
    reference = {"fx": 536.0735, "fy": 536.0164, "cx": 342.3705, "cy": 235.5369}
    for name, value in reference.items():
        assert getattr(sol, name) == pytest.approx(value, abs=REFERENCE_TOL_PX), name
    assert sol.rms_px == pytest.approx(0.408695, abs=1e-5)
    names = [n for n, _, _ in left_views]
    assert names[int(np.argmax(sol.per_view_rms_px))] == "left02.jpg"
    assert sol.per_view_rms_px.max() == pytest.approx(1.22, abs=0.005)
    assert "left02.jpg" in [names[i] for i in flag_outliers(sol).outlier_views]
    # the views scatter more than their corner noise explains: the reported sigma is the view-level one, the
    # Jacobian one behind it still agrees with OpenCV's
    cov = sol.covariance
    assert cov is not None and cov.view_factor is not None and cov.inflated and cov.view_factor > 1.5
    for name, value in sol.sigma_opencv.items():
        assert sol.sigma[name] / cov.view_factor == pytest.approx(value, rel=0.01), name


def test_udacity_reference_solve_flags_calibration15_and_its_bad_corner(udacity_views):
    """DATASET.md's reference solves all 17 detected views at 1280x720 (the two 1281x721 frames
    included, their corners taken as they are)."""
    names = [n for n, _, _ in udacity_views]
    obj = [model_points()] * len(udacity_views)
    sol = solve_intrinsics(obj, [c for _, c, _ in udacity_views], (1280, 720), "opencv-default")
    reference = {"fx": 1156.46, "fy": 1151.27, "cx": 671.32, "cy": 389.22}
    for name, value in reference.items():
        assert getattr(sol, name) == pytest.approx(value, abs=REFERENCE_TOL_PX), name
    assert sol.rms_px == pytest.approx(1.003, abs=5e-4)
    cov = sol.covariance  # per-view error beyond the corner noise: the view-level sigma is reported
    assert cov is not None and cov.view_factor is not None and cov.inflated
    for name, value in {
        "fx": 3.26,
        "fy": 3.55,
        "cx": 4.13,
        "cy": 3.02,
    }.items():  # the Jacobian sigma behind it
        assert sol.sigma[name] / cov.view_factor == pytest.approx(value, abs=0.005), name

    report = flag_outliers(sol, corner_ids_per_view=[np.arange(54)] * len(obj))
    assert [names[i] for i in report.outlier_views] == ["calibration15.jpg"]
    worst = report.outlier_corners[0]
    assert names[worst.view_index] == "calibration15.jpg"
    assert divmod(worst.corner_id, PATTERN[0]) == (5, 0)  # row 5, col 0
    assert worst.residual_px == pytest.approx(15.3, abs=0.1)
    np.testing.assert_array_equal(udacity_views[worst.view_index][1][worst.corner_id], [928.0, 604.0])


def test_udacity_without_the_1281x721_frames_still_exposes_the_bad_corner(udacity_views):
    """Solve only the frames that really are 1280x720; calibration15 (1281x721) is then checked as
    a held-out view: pose re-fitted with the intrinsics frozen, corner rule of the fit."""
    sizes = {n: s for n, _, s in udacity_views}
    assert sorted(n for n, s in sizes.items() if s == (1281, 721)) == [
        "calibration15.jpg",
        "calibration7.jpg",
    ]
    kept = [(n, c) for n, c, s in udacity_views if s == (1280, 720)]
    assert len(kept) == 15
    sol = solve_intrinsics([model_points()] * 15, [c for _, c in kept], (1280, 720), "opencv-default")
    assert flag_outliers(sol).outlier_views == ()  # nothing left to flag among the kept views
    corners15 = next(c for n, c, _ in udacity_views if n == "calibration15.jpg")
    residuals = refit_pose_residuals(model_points(), corners15, sol.camera_matrix, sol.dist_coeffs)
    threshold, _ = corner_outlier_threshold_px(sol.residuals_px)
    flagged = find_corner_outliers([residuals], threshold)
    assert divmod(flagged[0].corner_id, PATTERN[0]) == (5, 0)
    assert flagged[0].residual_px == pytest.approx(15.3, abs=0.5)
    view_rms = float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))
    assert view_rms > 2 * np.median(sol.per_view_rms_px)


@pytest.mark.parametrize("model", ["opencv-default", "k1k2"])
def test_udacity_bad_corner_is_removed_by_default_and_the_solve_improves(udacity_views, model):
    """The corner rule removes calibration15's row 5 col 0 (15.3 px) from the solve, as mrcal's outlier
    rejection does; mrcal drops 6-7 corners of these 918 in all (DATASET.md)."""
    names = [n for n, _, _ in udacity_views]
    obj, img = [model_points()] * len(udacity_views), [c for _, c, _ in udacity_views]
    kept_all = solve_intrinsics(obj, img, (1280, 720), model)
    rejection = solve_rejecting_corners(obj, img, (1280, 720), model)
    removed = {(names[c.view_index], divmod(c.corner_id, PATTERN[0])): c for c in rejection.rejected}
    bad = removed[("calibration15.jpg", (5, 0))]
    assert rejection.rejected[0] is bad and bad.residual_px > 10.0  # the worst one
    assert len(removed) <= 0.02 * sum(len(o) for o in obj)  # as sparing as mrcal's, within a few corners
    assert rejection.solution.rms_px < 0.9 * kept_all.rms_px
    assert names.index("calibration15.jpg") in flag_outliers(kept_all).outlier_views
    assert names.index("calibration15.jpg") not in flag_outliers(rejection.solution).outlier_views
