"""One board pose from one detected view with the intrinsics frozen: T_cam_board by solvePnP.

The hand-eye robot case turns every image into ``T_cam_board``. IPPE (planar targets) gives the
closed form, Levenberg-Marquardt on the reprojection error polishes it.
"""

from __future__ import annotations

import cv2
import numpy as np

from calibctl.core.extrinsics import se3

MIN_CORNERS = 4


def estimate_board_pose(object_points_m: np.ndarray, corners_px: np.ndarray, camera_matrix: np.ndarray,
                        dist_coeffs: np.ndarray) -> tuple[np.ndarray | None, float]:
    """Board pose from matched corners.

    Args:
        object_points_m: (N, 3) float64 board-frame points, metres (z = 0).
        corners_px: (N, 2) float64 detected corners, pixels.
        camera_matrix: (3, 3) px; dist_coeffs: (n,) OpenCV order.

    Returns:
        ((4, 4) T_cam_board or None when no pose fits, reprojection RMS in px (inf without a pose)).
    """
    obj = np.asarray(object_points_m, np.float64).reshape(-1, 1, 3)
    img = np.asarray(corners_px, np.float64).reshape(-1, 1, 2)
    if obj.shape[0] < MIN_CORNERS:
        return None, float("inf")
    K, dist = np.asarray(camera_matrix, np.float64), np.asarray(dist_coeffs, np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
        return None, float("inf")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    projected, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((projected - img).reshape(-1, 2) ** 2, axis=1))))
    return se3.transform(se3.rotation_from_rotvec(rvec.reshape(3)), tvec.reshape(3)), rms
