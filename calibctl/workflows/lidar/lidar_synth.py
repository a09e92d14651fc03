"""``calibctl lidar synth``: a rendered camera + VLP-16-like LiDAR set with known T_lidar_cam (tests, demos).

Writes ``images/poseN.png`` (pinhole 1280 x 960, core.synth's renderer; or, with ``--serial``, through that
camera's stored lens: its image size, K and distortion, pinhole or fisheye), ``scans/poseN.pcd`` (ASCII PCD
v0.7, x y z intensity ring), ``camera_info.yaml`` (the lens the images were rendered through) and
``truth.json`` (T_lidar_cam, the station box, the board, the camera); the sweeps come from core.lidar.render
with its noise, per-laser bias and optional range offset. A set rendered through a rig member's lens is what
``lidar solve --rig RIG --serial MEMBER`` solves for that member.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibctl.config import Settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics import se3
from calibctl.core.lidar import render
from calibctl.core.lidar.pcd import PointCloud
from calibctl.core.synth.fisheye import FisheyeCamera
from calibctl.core.synth.pinhole import PinholeCamera, render_view
from calibctl.errors import AlreadyExistsError, UsageError
from calibctl.files import file_errors, write_atomic


def pcd_ascii(cloud: PointCloud) -> str:
    """PCD v0.7 ASCII text of ``cloud`` (x y z intensity ring)."""
    n = len(cloud.points_m)
    intensity = cloud.intensity if cloud.intensity is not None else np.zeros(n)
    ring = cloud.ring if cloud.ring is not None else np.zeros(n, np.int64)
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity ring\n"
        f"SIZE 4 4 4 4 2\nTYPE F F F F U\nCOUNT 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {n}\nDATA ascii\n"
    )
    rows = "".join(
        f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {i:g} {int(r)}\n"
        for p, i, r in zip(cloud.points_m, intensity, ring, strict=True)
    )
    return head + rows


@dataclass(frozen=True)
class SynthLens:
    """The lens the images are rendered through: a stored calibration's (``ref`` SERIAL@V) or the default."""

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    fisheye: bool = False
    ref: str | None = None

    @classmethod
    def default(cls) -> SynthLens:
        return cls(render.K_RENDER, np.zeros(5), render.IMAGE_SIZE)

    @classmethod
    def of(cls, ref: str, model: str, K: Any, dist: Any, image_size: tuple[int, int]) -> SynthLens:
        """A stored calibration's lens; distortion terms the renderer has no model for are refused."""
        d = np.asarray(dist, np.float64).ravel()
        if model == "fisheye":
            return cls(np.asarray(K, np.float64), d[:4], image_size, True, ref)
        if np.any(d[5:] != 0.0):
            raise UsageError(
                f"{ref} is a {model} calibration (terms beyond k1 k2 p1 p2 k3): lidar synth renders only "
                "Brown-Conrady (5 terms) or fisheye lenses",
                "solve this camera's edge from real images (`calibctl lidar solve --rig RIG --serial "
                f"{ref.split('@')[0]}`)",
            )
        return cls(np.asarray(K, np.float64), np.pad(d[:5], (0, 5 - min(5, len(d)))), image_size, False, ref)

    def camera(self) -> PinholeCamera | FisheyeCamera:
        if self.fisheye:  # full frame; fov_deg only bounds pose draws, which the LiDAR session makes here
            return FisheyeCamera(self.K, self.dist, self.image_size, 180.0, None)
        return PinholeCamera(self.K, self.dist, self.image_size)

    def camera_info(self) -> str:
        """ROS camera_info YAML of the lens (``lidar solve --camera-info`` reads it)."""
        model = "equidistant" if self.fisheye else "plumb_bob"
        return (
            f"distortion_model: {model}\nwidth: {self.image_size[0]}\nheight: {self.image_size[1]}\n"
            f"K: {json.dumps(self.K.reshape(-1).tolist())}\nD: {json.dumps(self.dist.tolist())}\n"
        )


def stored_lens(settings: Settings, ref: str) -> SynthLens:
    """The lens of ``ref`` (SERIAL: its active calibration, the one ``lidar solve --serial`` poses the board
    with; SERIAL@N: that version) as the store holds it."""
    from calibctl.workflows.store_admin import records

    art = records.show(settings, ref)
    return SynthLens.of(art.ref, art.model.name, art.camera_matrix, art.dist_coeffs, art.image_size)


def run_lidar_synth(
    out: Path,
    n_poses: int,
    seed: int,
    range_offset_m: float = 0.0,
    one_way: bool = False,
    force: bool = False,
    lens: SynthLens | None = None,
) -> dict[str, Any]:
    """Render and write the set (module docstring) through ``lens`` (None: the default 1280 x 960 pinhole);
    AlreadyExistsError when ``out`` holds one and not ``force``."""
    lens = lens or SynthLens.default()
    truth_path = out / "truth.json"
    if truth_path.exists() and not force:
        raise AlreadyExistsError(f"{out} already holds a rendered set", "pass --force to overwrite it")
    session = render.render_session(n_poses, seed, range_offset_m=range_offset_m, one_way=one_way)
    camera = lens.camera()
    b = session.board
    spec = BoardSpec.chessboard(b.cols, b.rows, b.square_m)
    rng = np.random.default_rng(seed + 1_000_003)
    for d in ("images", "scans"):
        with file_errors("create", out / d):
            (out / d).mkdir(parents=True, exist_ok=True)
    for i, pose in enumerate(session.poses, start=1):
        T_cam_board = se3.invert(session.T_lidar_cam) @ pose.T_lidar_board
        image = render_view(camera, spec, T_cam_board, rng, supersample=2)
        ok, png = cv2.imencode(".png", image)
        write_atomic(out / "images" / f"pose{i}.png", png.tobytes(), force=force)
        write_atomic(out / "scans" / f"pose{i}.pcd", pcd_ascii(pose.cloud), force=force)
    truth = {
        "T_lidar_cam": session.T_lidar_cam.tolist(),
        "range_offset_mm": range_offset_m * 1e3,
        "box": ",".join(f"{v:g}" for v in (*session.box.lower_m, *session.box.upper_m)),
        "board": {
            "cols": b.cols,
            "rows": b.rows,
            "square_mm": b.square_m * 1e3,
            "backing_mm": [v * 1e3 for v in b.backing_m],
            "pattern_offset_mm": [v * 1e3 for v in b.offset_m],
        },
        "camera_info": "camera_info.yaml",
        "camera": lens.ref,
        "poses": n_poses,
        "seed": seed,
        "one_way": one_way,
    }
    write_atomic(out / "camera_info.yaml", lens.camera_info(), force=True)
    write_atomic(truth_path, json.dumps(truth, indent=2) + "\n", force=True)
    return {
        "out": str(out),
        "poses": n_poses,
        "seed": seed,
        "truth": str(truth_path),
        "box": truth["box"],
        "camera": lens.ref,
    }
