"""Checks of a camera-LiDAR solution: k-fold held-out residuals, the range offset the board sizes ask
for, and the Euler angles other tools publish (acfr/cam_lidar_calibration's roll, pitch, yaw).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from calibctl.core.lidar.segment import BoardInScan
from calibctl.core.lidar.solve import Pose, pose_residuals, solve
from calibctl.core.lidar.target import BackingBoard


def held_out(
    poses: Sequence[Pose],
    board: BackingBoard,
    folds: int = 5,
    edge_px: Callable[[np.ndarray, Sequence[Pose]], np.ndarray] | None = None,
) -> tuple[float, float, float]:
    """k-fold over poses: (point-to-plane RMS m, edge RMS m, edge RMS px) of each pose when it was left out.
    ``edge_px(T_lidar_cam, poses)``: each ring end point's distance to the board's outline in the image, px
    (the lens lives above core); without it the pixel figure is NaN."""
    plane, edge, px = [], [], []
    for f in range(folds):
        test = [p for i, p in enumerate(poses) if i % folds == f]
        train = [p for i, p in enumerate(poses) if i % folds != f]
        if not test or len(train) < 3:
            continue
        sol = solve(train, board)
        for p in test:
            pr, er = pose_residuals(sol.T_lidar_cam, p.camera.T_cam_board, p, board)
            plane.append(pr)
            edge.append(er)
        if edge_px is not None:
            px.append(edge_px(sol.T_lidar_cam, test))
    if not plane:
        return float("nan"), float("nan"), float("nan")
    rms_px = float(np.sqrt(np.mean(np.concatenate(px) ** 2))) if px else float("nan")
    return (
        float(np.sqrt(np.mean(np.concatenate(plane) ** 2))),
        float(np.sqrt(np.mean(np.concatenate(edge) ** 2))),
        rms_px,
    )


def rpy_from_rotation(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) rad with R = Rz(yaw) Ry(pitch) Rx(roll) (acfr's Rotation::toMat, tf's setRPY)."""
    return (
        float(np.arctan2(R[2, 1], R[2, 2])),
        float(-np.arcsin(np.clip(R[2, 0], -1, 1))),
        float(np.arctan2(R[1, 0], R[0, 0])),
    )


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def range_offset_from_dimensions(
    boards: Sequence[BoardInScan], backing_m: tuple[float, float]
) -> tuple[float, float]:
    """The range correction (added to every range, acfr's ``distance_offset_mm``) the board sizes ask for:
    ranges long by dr scale a board at range r by (r + dr) / r, so the correction is -error / size * r;
    (mean, sigma) m."""
    est = [-e / s * b.range_m for b in boards for e, s in zip(b.dimension_error_m, backing_m, strict=True)]
    if len(est) < 2:
        return float("nan"), float("nan")
    # the two sides of one board share its range: count boards, not sides, in the sigma
    return float(np.mean(est)), float(np.std(est, ddof=1) / np.sqrt(len(boards)))


def camera_to_lidar_scale(poses: Sequence[Pose], board: BackingBoard) -> float:
    """Median over pose pairs of (distance between the board centres as the camera places them) / (the same
    distance as the LiDAR measures it). Distances between poses do not depend on T_lidar_cam, so this is 1
    up to noise when the pattern's square size is right; the camera's poses scale with the square size, so a
    square given 100 mm on a 95 mm board reads 1.053. NaN with fewer than two poses or no pair 0.2 m apart."""
    centre = board.centre_in_pattern()
    cam = np.array([p.camera.T_cam_board[:3, :3] @ centre + p.camera.T_cam_board[:3, 3] for p in poses])
    lid = np.array([p.lidar.centre_m for p in poses])
    ratios = []
    for i in range(len(poses)):
        for j in range(i + 1, len(poses)):
            d_lidar = float(np.linalg.norm(lid[i] - lid[j]))
            if d_lidar >= 0.2:  # metres: shorter moves are dominated by the centres' noise
                ratios.append(float(np.linalg.norm(cam[i] - cam[j])) / d_lidar)
    return float(np.median(ratios)) if ratios else float("nan")
