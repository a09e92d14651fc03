"""Synchronised synthetic rigs of 2-4 cameras with known intrinsics and extrinsics (ground truth).

Cameras: camera 0 is the root; camera i sits ``baselines_m[i-1]`` further along the root's x axis
(with a few mm of y/z offset) and is turned by a small yaw, pitch and roll, so baselines and relative
rotations differ between cameras. Each camera has its own focal length and principal point and the
seed's k1, k2 (p1 = p2 = k3 = 0, so the production k1k2 model is exact).

Board poses: tilted 20-38 deg toward cycling directions, placed on targets spread over the view of a
virtual camera at the rig's centre; a pose is kept when at least ``min_cameras`` cameras see the
whole board (``synth_scenes.fits_in_frame``). Corners come from ``true_corners_px`` (the renderer's own
camera model); ``render_rig_frame`` renders the photos. Everything comes from the caller's seeded rng.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.synth.pinhole import Photometry, PinholeCamera, render_view, true_corners_px
from calibctl.core.synth.scenes import default_distance_range_m, fits_in_frame, place_board, tilt_rotation

MAX_POSE_DRAWS = 400
RIG_DIST = (-0.2814, 0.0977, 0.0, 0.0, 0.0)  # the seed's k1 k2 only


@dataclass(frozen=True)
class RigTruth:
    """Ground truth of a synthetic rig.

    Attributes:
        names: camera frame names, names[0] is the root.
        cameras: per camera true intrinsics.
        T_root_cam: per camera (4, 4) float64, metres (the root's is identity).
        T_root_board: per frame (4, 4) float64, metres.
    """

    names: tuple[str, ...]
    cameras: tuple[PinholeCamera, ...]
    T_root_cam: tuple[np.ndarray, ...]
    T_root_board: tuple[np.ndarray, ...]

    def T_cam_board(self, c: int, f: int) -> np.ndarray:
        return np.linalg.inv(self.T_root_cam[c]) @ self.T_root_board[f]

    def sees(self, board: BoardSpec, c: int, f: int) -> bool:
        return fits_in_frame(self.cameras[c], board, self.T_cam_board(c, f))


def rig_cameras(
    n_cameras: int,
    rng: np.random.Generator,
    image_size: tuple[int, int] = (640, 480),
    baselines_m: tuple[float, ...] | None = None,
    max_rotation_deg: float = 4.0,
) -> tuple[tuple[PinholeCamera, ...], tuple[np.ndarray, ...]]:
    """Intrinsics and T_root_cam of ``n_cameras`` cameras in a row (see module docstring)."""
    if not 2 <= n_cameras <= 4:
        raise ValueError(f"a synthetic rig has 2-4 cameras, got {n_cameras}")
    baselines = baselines_m or tuple(float(b) for b in rng.uniform(0.06, 0.12, n_cameras - 1))
    if len(baselines) != n_cameras - 1:
        raise ValueError(f"{n_cameras} cameras need {n_cameras - 1} baselines, got {len(baselines)}")
    width, height = image_size
    cams, poses = [], []
    x = 0.0
    for c in range(n_cameras):
        f = width / 640.0 * float(rng.uniform(760.0, 840.0))
        K = np.array(
            [
                [f, 0.0, (width - 1) / 2 + rng.uniform(-8, 8)],
                [0.0, f, (height - 1) / 2 + rng.uniform(-8, 8)],
                [0.0, 0.0, 1.0],
            ]
        )
        cams.append(PinholeCamera(K, np.array(RIG_DIST), (int(width), int(height))))
        T = np.eye(4)
        if c > 0:
            x += baselines[c - 1]
            angles = np.deg2rad(rng.uniform(-max_rotation_deg, max_rotation_deg, 3))
            T[:3, :3] = cv2.Rodrigues(angles)[0]
            T[:3, 3] = [x, rng.uniform(-0.004, 0.004), rng.uniform(-0.004, 0.004)]
        poses.append(T)
    return tuple(cams), tuple(poses)


def _virtual_camera(
    cams: tuple[PinholeCamera, ...], T_root_cam: tuple[np.ndarray, ...]
) -> tuple[PinholeCamera, np.ndarray]:
    T = np.eye(4)
    T[:3, 3] = np.mean([p[:3, 3] for p in T_root_cam], axis=0)
    return cams[0], T


def synthesize_rig(
    n_cameras: int,
    board: BoardSpec,
    n_frames: int,
    rng: np.random.Generator,
    image_size: tuple[int, int] = (640, 480),
    baselines_m: tuple[float, ...] | None = None,
    min_cameras: int | None = None,
) -> RigTruth:
    """A seeded rig and ``n_frames`` board poses seen by at least ``min_cameras`` (default all) cameras."""
    cams, T_root_cam = rig_cameras(n_cameras, rng, image_size, baselines_m)
    need = n_cameras if min_cameras is None else min_cameras
    virtual, T_root_virtual = _virtual_camera(cams, T_root_cam)
    width, height = image_size
    near = default_distance_range_m(virtual, board, (0.45, 0.65))
    frames: list[np.ndarray] = []
    truth = RigTruth(tuple(f"CAM{c}" for c in range(n_cameras)), cams, T_root_cam, ())
    for i in range(n_frames):
        for _ in range(MAX_POSE_DRAWS):
            cell = rng.uniform(-0.28, 0.28, 2)
            target = ((0.5 + cell[0]) * width, (0.5 + cell[1]) * height)
            R = tilt_rotation(
                np.deg2rad(rng.uniform(20.0, 38.0)),
                2 * np.pi * i / 8 + rng.uniform(-0.3, 0.3),
                float(rng.uniform(-0.2, 0.2)),
            )
            T_root_board = T_root_virtual @ place_board(virtual, board, R, target, float(rng.uniform(*near)))
            candidate = RigTruth(truth.names, cams, T_root_cam, (T_root_board,))
            if sum(candidate.sees(board, c, 0) for c in range(n_cameras)) >= need:
                frames.append(T_root_board)
                break
        else:
            raise ValueError("cannot place the board where enough rig cameras see it; use a smaller board")
    return RigTruth(truth.names, cams, T_root_cam, tuple(frames))


def rig_corners(
    truth: RigTruth, board: BoardSpec, noise_px: float, rng: np.random.Generator
) -> list[list[np.ndarray | None]]:
    """Per frame, per camera: (N, 2) noisy true corners (Gaussian per coordinate) or None when not seen."""
    out = []
    for f in range(len(truth.T_root_board)):
        row: list[np.ndarray | None] = []
        for c, cam in enumerate(truth.cameras):
            if truth.sees(board, c, f):
                px = true_corners_px(cam, board, truth.T_cam_board(c, f))
                row.append(px + rng.normal(0.0, noise_px, px.shape))
            else:
                row.append(None)
        out.append(row)
    return out


def render_rig_frame(
    truth: RigTruth, board: BoardSpec, f: int, rng: np.random.Generator, supersample: int = 6
) -> list[np.ndarray | None]:
    """Per camera (H, W) uint8 photo of frame ``f`` (None where the camera does not see the whole board)."""
    photometry = Photometry.random(rng)
    return [
        render_view(cam, board, truth.T_cam_board(c, f), rng, photometry, supersample=supersample)
        if truth.sees(board, c, f)
        else None
        for c, cam in enumerate(truth.cameras)
    ]
