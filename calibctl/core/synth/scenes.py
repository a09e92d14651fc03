"""Board poses for synthetic sessions: one scenario per capture outcome, plus a hand-held video.

Tilt convention (shared with ``gates``): a view's tilt is the angle between the board normal and the
optical axis; its direction is the image direction (x right, y down) of the board side that is
farther from the camera. Scenarios:

- ``good``: tilts 20-40 deg, directions cycling through 8 evenly spread azimuths, the board placed so
  its corners reach all nine cells of a 3x3 grid over the image. Passes every gate.
- ``flat``: the same placements with tilts under 5 deg (fails observability, and with it the tilt
  gate, whose lower bound is 20 deg).
- ``centre``: good tilts, but the board far away and in the middle cell only (fails coverage).
- ``one-direction``: good tilts and coverage, every tilt toward the right (fails the tilt gate).
- ``video``: a smooth hand-held trajectory through ``good`` key poses, still for a few frames at each
  key pose (with sub-pixel tremor) and moving in between.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.board.board_spec import APRILGRID, BoardSpec
from calibctl.core.synth.pinhole import PinholeCamera, undistort_normalised

SCENARIOS = ("good", "flat", "centre", "one-direction", "video")
IMAGE_MARGIN_PX_FRAC = 0.02  # keep the whole board (with its quiet zone) this far inside the frame
MIN_SQUARE_PX_AT_640 = 11.0  # smallest projected square edge we place, at the 640-wide reference...
MIN_SQUARE_PX = 8.0  # ...and at any resolution: below this the detectors give up


@dataclass(frozen=True)
class VideoPlan:
    """Frame poses of a synthetic video and which frames are still (key poses)."""

    poses: list[np.ndarray]
    still: list[bool]
    key_index: list[int]


def tilt_rotation(tilt_rad: float, direction_rad: float, spin_rad: float) -> np.ndarray:
    """(3, 3) R_cam_board: spin about the board normal, then tilt so the far side lies toward
    image azimuth ``direction_rad`` (0 = right, pi/2 = down)."""
    spin = cv2.Rodrigues(np.array([0.0, 0.0, spin_rad]))[0]
    axis = np.array([np.sin(direction_rad), -np.cos(direction_rad), 0.0])
    return cv2.Rodrigues(axis * tilt_rad)[0] @ spin


def place_board(
    camera: PinholeCamera, board: BoardSpec, R: np.ndarray, target_px: tuple[float, float], distance_m: float
) -> np.ndarray:
    """(4, 4) T_cam_board with the board centre on the ray through ``target_px`` at depth ``distance_m``.

    An AprilGrid's frame is Kalibr's (``y`` up the print, ``z`` out of its face, toward the camera), so
    ``R`` is turned by 180 degrees about the board's ``x`` for it: the camera still sees the printed face.
    """
    K = camera.K
    yd = (target_px[1] - K[1, 2]) / K[1, 1]
    xd = (target_px[0] - K[0, 2]) / K[0, 0]
    x, y = undistort_normalised(np.array([xd]), np.array([yd]), camera.dist)
    centre_board = board.centre_m()
    if board.kind == APRILGRID:
        R = R @ np.diag([1.0, -1.0, -1.0])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = distance_m * np.array([x[0], y[0], 1.0]) - R @ centre_board
    return T


def outline_points(board: BoardSpec, margin_squares: float = 1.0, per_edge: int = 12) -> np.ndarray:
    """(M, 3) points along the printed outline (quiet zone included), board frame, metres."""
    (lo_x, lo_y), (hi_x, hi_y) = board.printed_bounds()
    lo, hx, hy = min(lo_x, lo_y) - margin_squares, hi_x + margin_squares, hi_y + margin_squares
    s = np.linspace(0.0, 1.0, per_edge, endpoint=False)
    xs = np.concatenate([lo + (hx - lo) * s, np.full_like(s, hx), hx - (hx - lo) * s, np.full_like(s, lo)])
    ys = np.concatenate([np.full_like(s, lo), lo + (hy - lo) * s, np.full_like(s, hy), hy - (hy - lo) * s])
    return np.column_stack([xs, ys, np.zeros_like(xs)]) * board.square_size_m


def fits_in_frame(camera: PinholeCamera, board: BoardSpec, T_cam_board: np.ndarray) -> bool:
    """True when the whole board with its quiet zone is in front of the camera and inside the frame."""
    outline = outline_points(board)
    depth = (T_cam_board[:3, :3] @ outline.T + T_cam_board[:3, 3:4])[2]
    if np.any(depth <= 0.05):
        return False
    width, height = camera.image_size
    pad = IMAGE_MARGIN_PX_FRAC * max(width, height)
    px = camera.project(outline, T_cam_board)
    inside = (
        (px[:, 0] >= pad) & (px[:, 0] <= width - 1 - pad) & (px[:, 1] >= pad) & (px[:, 1] <= height - 1 - pad)
    )
    if not np.all(inside):
        return False
    corners = camera.project(board.object_points(), T_cam_board).reshape(board.rows, board.cols, 2)
    step = 2 if board.kind == APRILGRID else 1  # an AprilGrid's tag edges, not the gaps between tags
    edge_px = min(
        np.linalg.norm(np.diff(corners, axis=1)[:, ::step], axis=2).min(),
        np.linalg.norm(np.diff(corners, axis=0)[::step], axis=2).min(),
    )
    return bool(edge_px >= max(MIN_SQUARE_PX, MIN_SQUARE_PX_AT_640 * width / 640.0))


def _cell_targets(camera: PinholeCamera, n: int) -> list[tuple[float, float]]:
    """Board-centre targets cycling through the 3x3 cells, corners first (they are the hard ones)."""
    width, height = camera.image_size
    order = [(0, 0), (2, 2), (2, 0), (0, 2), (1, 1), (1, 0), (1, 2), (0, 1), (2, 1)]
    return [
        ((0.5 + 0.42 * (cx - 1)) * width, (0.5 + 0.42 * (cy - 1)) * height)
        for cx, cy in (order[i % len(order)] for i in range(n))
    ]


def _sample_pose(
    camera: PinholeCamera,
    board: BoardSpec,
    rng: np.random.Generator,
    target: tuple[float, float],
    tilt_rad: float,
    direction_rad: float,
    distance_range_m: tuple[float, float],
) -> np.ndarray:
    """Place the board as close to ``target`` as fits: pull the target toward the centre until it does."""
    width, height = camera.image_size
    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    spin = float(rng.uniform(-0.2, 0.2))
    for attempt in range(200):
        pull = min(1.0, attempt / 60.0)
        tgt = np.array(target) + (centre - np.array(target)) * pull
        distance = float(rng.uniform(*distance_range_m)) * (1.0 + 0.01 * max(0, attempt - 60))
        T = place_board(
            camera, board, tilt_rotation(tilt_rad, direction_rad, spin), (tgt[0], tgt[1]), distance
        )
        if fits_in_frame(camera, board, T):
            return T
    raise ValueError("cannot place the board inside the frame; use a smaller board or a wider image")


def default_distance_range_m(
    camera: PinholeCamera, board: BoardSpec, fill: tuple[float, float]
) -> tuple[float, float]:
    """Distances at which the board spans ``fill`` (fractions) of the image width."""
    width = camera.image_size[0]
    (lo_x, _), (hi_x, _) = board.printed_bounds()
    board_w_m = (hi_x - lo_x + 2) * board.square_size_m  # the pattern and a square of quiet zone each side
    f = camera.K[0, 0]
    return f * board_w_m / (fill[1] * width), f * board_w_m / (fill[0] * width)


def scenario_poses(
    scenario: str, camera: PinholeCamera, board: BoardSpec, n_views: int, rng: np.random.Generator
) -> list[np.ndarray]:
    """(4, 4) T_cam_board per view for a still-image scenario (everything but ``video``)."""
    if scenario not in SCENARIOS or scenario == "video":
        raise ValueError(f"unknown still scenario {scenario!r}")
    near = default_distance_range_m(camera, board, (0.55, 0.75))
    targets = _cell_targets(camera, n_views)
    poses = []
    for i in range(n_views):
        jitter = float(rng.uniform(-0.2, 0.2))
        direction = 2 * np.pi * i / 8 + jitter
        tilt = np.deg2rad(rng.uniform(22.0, 38.0))
        target, dist_range = targets[i], near
        if scenario == "flat":
            tilt = np.deg2rad(rng.uniform(0.5, 4.0))
        elif scenario == "one-direction":
            direction = float(rng.uniform(-0.2, 0.2))
        elif scenario == "centre":
            width, height = camera.image_size
            target = ((0.5 + rng.uniform(-0.03, 0.03)) * width, (0.5 + rng.uniform(-0.03, 0.03)) * height)
            dist_range = default_distance_range_m(camera, board, (0.28, 0.3))
        poses.append(_sample_pose(camera, board, rng, target, tilt, direction, dist_range))
    return poses


def sweep_poses(
    camera: PinholeCamera,
    board: BoardSpec,
    n_views: int,
    rng: np.random.Generator,
    tilt_deg: tuple[float, float] = (0.0, 50.0),
) -> tuple[list[np.ndarray], list[float]]:
    """Poses for measuring tilt readout: tilt uniform in ``tilt_deg``, any direction, the board centre
    aimed anywhere in the frame (edges included) at 30-70 % fill. Returns (T_cam_board list, true tilts)."""
    width, height = camera.image_size
    dist_range = default_distance_range_m(camera, board, (0.3, 0.7))
    poses, tilts = [], []
    for _ in range(n_views):
        tilt = float(rng.uniform(*tilt_deg))
        target = (float(rng.uniform(0.03, 0.97)) * width, float(rng.uniform(0.03, 0.97)) * height)
        T = _sample_pose(
            camera, board, rng, target, np.deg2rad(tilt), float(rng.uniform(0, 2 * np.pi)), dist_range
        )
        poses.append(T)
        tilts.append(float(np.degrees(np.arccos(min(1.0, abs(T[2, 2]))))))
    return poses, tilts


def _interpolate(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Pose on the geodesic from T0 to T1 at fraction s (rotation by axis-angle, translation linear)."""
    delta = cv2.Rodrigues(T1[:3, :3] @ T0[:3, :3].T)[0].reshape(3)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(delta * s)[0] @ T0[:3, :3]
    T[:3, 3] = (1 - s) * T0[:3, 3] + s * T1[:3, 3]
    return T


def video_plan(
    camera: PinholeCamera,
    board: BoardSpec,
    n_keys: int,
    rng: np.random.Generator,
    still_frames: int = 4,
    move_frames: int = 6,
    tremor_m: float = 2e-5,
) -> VideoPlan:
    """A hand-held sweep: ``still_frames`` nearly still frames at each key pose, ``move_frames`` between."""
    keys = scenario_poses("good", camera, board, n_keys, rng)
    poses: list[np.ndarray] = []
    still: list[bool] = []
    key_index: list[int] = []
    for k, key in enumerate(keys):
        for _ in range(still_frames):
            T = key.copy()
            T[:3, 3] += rng.normal(0.0, tremor_m, 3)
            poses.append(T)
            still.append(True)
            key_index.append(k)
        if k + 1 < len(keys):
            for j in range(1, move_frames + 1):
                s = j / (move_frames + 1)
                s = s * s * (3 - 2 * s)  # ease in and out, like a hand
                poses.append(_interpolate(key, keys[k + 1], s))
                still.append(False)
                key_index.append(-1)
    return VideoPlan(poses, still, key_index)
