"""A camera + a VLP-16-like ring LiDAR seeing a diamond-held backing board, with known T_lidar_cam.

The LiDAR has 16 rings from -15 to +15 degrees (2 degree steps) and ``azimuth_step_deg`` between
firings; each ray hitting the backing board returns its range plus Gaussian noise (``range_noise_m``),
a per-laser bias (``laser_bias_m``, fixed per ring for the whole session, as a real unit's) and an
optional ``range_offset_m`` (a mis-set range calibration: acfr's VLP-16 needed -30 mm). A post behind
the board adds clutter inside the station box; every other ray ends on a wall 8 m away (a full sweep). The
camera is a pinhole (f 1000 px, 1280 x 960); its board pose comes from the projected inner corners plus
``corner_noise_px`` through the same ``estimate_board_pose`` the real images use, so its covariance is the one
a real view gets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.board.board_geometry import chessboard_object_points
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.lidar.pcd import PointCloud
from calibctl.core.lidar.segment import StationBox
from calibctl.core.lidar.target import BackingBoard, CameraBoard, pose_covariance

VLP16_ELEVATIONS_DEG = tuple(float(e) for e in np.arange(-15.0, 15.1, 2.0))
K_RENDER = np.array([[1000.0, 0.0, 640.0], [0.0, 1000.0, 480.0], [0.0, 0.0, 1.0]])
IMAGE_SIZE = (1280, 960)
ACFR_BOARD = BackingBoard(cols=5, rows=7, square_m=0.095, backing_m=(0.61, 0.85), offset_m=(0.002, 0.0))
WALL_M = 8.0
RENDER_BOX = StationBox((0.8, -2.5, -1.2), (4.5, 2.5, 1.2))
# camera looks along LiDAR x: cam z = lidar x, cam x = -lidar y, cam y = -lidar z
R_LIDAR_CAM_NOMINAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class RenderedPose:
    """One pose: the sweep, the camera's board, the true T_lidar_board (4, 4)."""

    cloud: PointCloud
    camera: CameraBoard | None
    T_lidar_board: np.ndarray


@dataclass(frozen=True)
class RenderedSession:
    """Truth and data: T_lidar_cam (4, 4), the poses, the board and the station box; ``laser_bias_m`` (rings,)
    the bias added to each ring's ranges (metres)."""

    T_lidar_cam: np.ndarray
    poses: tuple[RenderedPose, ...]
    board: BackingBoard
    box: StationBox
    range_offset_m: float
    laser_bias_m: np.ndarray


def true_T_lidar_cam(rng: np.random.Generator) -> np.ndarray:
    """Camera ~0.2 m below and 0.06 m ahead of the LiDAR, looking forward, a few degrees off nominal."""
    R = se3.rotation_from_rotvec(rng.normal(0.0, np.radians(3.0), 3)) @ R_LIDAR_CAM_NOMINAL
    return se3.transform(R, np.array([0.06, 0.0, -0.2]) + rng.normal(0.0, 0.02, 3))


def board_pose(rng: np.random.Generator, one_way: bool) -> np.ndarray:
    """T_lidar_board: board centre 1.6-3.2 m ahead, held as a diamond, turned and tilted at random
    (``one_way``: every board square to the LiDAR, as an operator who never tilts it)."""
    rng_m = rng.uniform(1.6, 3.2)
    az = rng.uniform(-0.35, 0.35)
    centre = np.array([rng_m * np.cos(az), rng_m * np.sin(az), rng.uniform(-0.15, 0.15)])
    # board frame: z away from the sensors, x/y in the board plane; start square to the LiDAR's x axis
    R0 = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    spin = np.radians(45.0 + (0.0 if one_way else rng.uniform(-8, 8)))
    R_spin = se3.rotation_from_rotvec([0.0, 0.0, spin])
    if one_way:
        R_tilt = np.eye(3)
    else:
        R_tilt = se3.rotation_from_rotvec([0.0, rng.uniform(-0.45, 0.45), 0.0]) @ se3.rotation_from_rotvec(
            [0.0, 0.0, rng.uniform(-0.6, 0.6)]
        )  # pitch about y, turn about z (LiDAR)
    return se3.transform(R_tilt @ R0 @ R_spin, centre)


def _sweep(
    T_lidar_board: np.ndarray,
    board: BackingBoard,
    rng: np.random.Generator,
    azimuth_step_deg: float,
    range_noise_m: float,
    laser_bias_m: np.ndarray,
    range_offset_m: float,
    clutter: bool = True,
) -> PointCloud:
    elev = np.radians(np.array(VLP16_ELEVATIONS_DEG))
    az = np.radians(np.arange(-180.0, 180.0, azimuth_step_deg)) + rng.uniform(0, np.radians(azimuth_step_deg))
    E, A = np.meshgrid(elev, az, indexing="ij")
    rays = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1).reshape(-1, 3)
    ring = np.repeat(np.arange(len(elev)), len(az))
    n, origin = T_lidar_board[:3, 2], T_lidar_board[:3, 3]
    centre = origin  # T_lidar_board here is the backing board's centre frame
    denom = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        r_board = (centre @ n) / denom
    hit_pts = rays * r_board[:, None]
    local = (hit_pts - centre) @ T_lidar_board[:3, :3]
    on_board = (
        (r_board > 0)
        & (np.abs(local[:, 0]) <= board.backing_m[0] / 2)
        & (np.abs(local[:, 1]) <= board.backing_m[1] / 2)
    )
    # a post 0.4 m behind the board's centre, 5 cm wide, from the floor to the board: clutter in the box
    post = origin + 0.4 * n
    r_post = np.linalg.norm(post[:2])
    az_post = np.arctan2(post[1], post[0])
    on_post = (
        clutter
        & (~on_board)
        & (np.abs(np.angle(np.exp(1j * (A.reshape(-1) - az_post)))) < 0.025 / r_post)
        & (np.tan(E.reshape(-1)) * r_post < post[2] - 0.3)
    )
    # every other ray ends on a round room's wall WALL_M away: a full ~29k-point sweep, outside the box
    r_wall = WALL_M / np.maximum(np.cos(E.reshape(-1)), 1e-9)
    r = np.where(
        on_board, r_board, np.where(on_post, r_post / np.maximum(np.cos(E.reshape(-1)), 1e-9), r_wall)
    )
    keep = np.isfinite(r)
    r = r[keep] + rng.normal(0.0, range_noise_m, keep.sum()) + laser_bias_m[ring[keep]] - range_offset_m
    return PointCloud(rays[keep] * r[:, None], np.full(keep.sum(), 50.0), ring[keep])


def render_session(
    n_poses: int,
    seed: int,
    *,
    range_noise_m: float = 0.01,
    laser_bias_m: float = 0.005,
    range_offset_m: float = 0.0,
    corner_noise_px: float = 0.2,
    azimuth_step_deg: float = 0.2,
    one_way: bool = False,
    board: BackingBoard = ACFR_BOARD,
    clutter: bool = True,
) -> RenderedSession:
    """``n_poses`` seeded poses (module docstring); ``range_offset_m`` is the correction the LiDAR needs
    (its ranges are short by it), acfr's ``distance_offset_mm`` convention."""
    rng = np.random.default_rng(seed)
    T_lidar_cam = true_T_lidar_cam(rng)
    biases = (
        rng.normal(0.0, laser_bias_m, len(VLP16_ELEVATIONS_DEG))
        if laser_bias_m > 0
        else np.zeros(len(VLP16_ELEVATIONS_DEG))
    )
    obj = chessboard_object_points(board.cols, board.rows, board.square_m)
    poses = []
    for _ in range(n_poses):
        T_lidar_centre = board_pose(rng, one_way)
        # pattern frame from the backing board's centre frame
        T_lidar_board = T_lidar_centre @ se3.transform(np.eye(3), -board.centre_in_pattern())
        T_cam_board = se3.invert(T_lidar_cam) @ T_lidar_board
        pts = obj @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
        px = pts[:, :2] / pts[:, 2:] * K_RENDER[0, 0] + K_RENDER[:2, 2]
        px = px + rng.normal(0.0, corner_noise_px, px.shape)
        T_est, _ = estimate_board_pose(obj, px, K_RENDER, np.zeros(5))
        camera = None
        if T_est is not None:
            cov, rms = pose_covariance(T_est, obj, px, K_RENDER, np.zeros(5), "k1k2")
            camera = CameraBoard(T_est, cov, rms)
        cloud = _sweep(
            T_lidar_centre, board, rng, azimuth_step_deg, range_noise_m, biases, range_offset_m, clutter
        )
        poses.append(RenderedPose(cloud, camera, T_lidar_board))
    return RenderedSession(T_lidar_cam, tuple(poses), board, RENDER_BOX, range_offset_m, biases)
