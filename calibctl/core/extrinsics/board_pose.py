"""One board pose from one detected view with the intrinsics frozen: T_cam_board by solvePnP.

The hand-eye robot case turns every image into ``T_cam_board`` through the calibration's own lens
model. A pinhole model: IPPE (planar targets) gives the closed form, Levenberg-Marquardt on the
reprojection error polishes it (OpenCV's own, cv2.solvePnPRefineLM: a solved problem in a well-kept
library, so it does not go through calibctl.core.lm). A fisheye model: ``core.intrinsics.solve.fit_pose``
(undistort through cv2.fisheye, then calibctl.core.lm on the fisheye projection:
``fisheye_model.refine_fisheye_pose``), as the rig solve does for its fisheye members; its four
coefficients are k1..k4 of the equidistant model, and solvePnP would read them as k1 k2 p1 p2.
"""

from __future__ import annotations

import cv2
import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.intrinsics.solve import DEFAULT_MODEL, fit_pose, is_fisheye, project_points

MIN_CORNERS = 4


def estimate_board_pose(
    object_points_m: np.ndarray,
    corners_px: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str = DEFAULT_MODEL,
) -> tuple[np.ndarray | None, float]:
    """Board pose from matched corners.

    Args:
        object_points_m: (N, 3) float64 board-frame points, metres (z = 0).
        corners_px: (N, 2) float64 detected corners, pixels.
        camera_matrix: (3, 3) px; dist_coeffs: (n,) in the order of ``model`` (OpenCV's, or k1..k4 of a
        fisheye).
        model: the calibration's model name (core.intrinsics.solve.MODELS); pinhole models all project alike.

    Returns:
        ((4, 4) T_cam_board or None when no pose fits, reprojection RMS in px (inf without a pose)).
    """
    obj = np.asarray(object_points_m, np.float64).reshape(-1, 1, 3)
    img = np.asarray(corners_px, np.float64).reshape(-1, 1, 2)
    if obj.shape[0] < MIN_CORNERS:
        return None, float("inf")
    K, dist = np.asarray(camera_matrix, np.float64), np.asarray(dist_coeffs, np.float64)
    rvec: np.ndarray
    tvec: np.ndarray
    if is_fisheye(model):
        pose = fit_pose(obj, img, K, dist, model)
        if pose is None:
            return None, float("inf")
        rvec, tvec = (
            np.asarray(pose[0], np.float64).reshape(3, 1),
            np.asarray(pose[1], np.float64).reshape(3, 1),
        )
    else:
        ok, rvec0, tvec0 = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
        if not ok or not (np.isfinite(rvec0).all() and np.isfinite(tvec0).all()):
            return None, float("inf")
        refined = cv2.solvePnPRefineLM(obj, img, K, dist, rvec0, tvec0)
        rvec, tvec = np.asarray(refined[0], np.float64), np.asarray(refined[1], np.float64)
    if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
        return None, float("inf")
    projected = project_points(obj, rvec, tvec, K, dist, model)
    rms = float(np.sqrt(np.mean(np.sum((projected - img.reshape(-1, 2)) ** 2, axis=1))))
    return se3.transform(se3.rotation_from_rotvec(rvec.reshape(3)), tvec.reshape(3)), rms
