"""``calibctl lidar synth``: a rendered camera + VLP-16-like LiDAR set with known T_lidar_cam (tests, demos).

Writes ``images/poseN.png`` (pinhole 1280 x 960, core.synth's renderer), ``scans/poseN.pcd`` (ASCII PCD
v0.7, x y z intensity ring) and ``truth.json`` (T_lidar_cam, the station box, the board); the sweeps
come from core.lidar.render with its noise, per-laser bias and optional range offset.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics import se3
from calibctl.core.lidar import render
from calibctl.core.lidar.pcd import PointCloud
from calibctl.core.synth.pinhole import PinholeCamera, render_view
from calibctl.errors import AlreadyExistsError
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


def run_lidar_synth(
    out: Path,
    n_poses: int,
    seed: int,
    range_offset_m: float = 0.0,
    one_way: bool = False,
    force: bool = False,
) -> dict[str, Any]:
    """Render and write the set (module docstring); AlreadyExistsError when ``out`` holds one and not
    ``force``."""
    truth_path = out / "truth.json"
    if truth_path.exists() and not force:
        raise AlreadyExistsError(f"{out} already holds a rendered set", "pass --force to overwrite it")
    session = render.render_session(n_poses, seed, range_offset_m=range_offset_m, one_way=one_way)
    camera = PinholeCamera(render.K_RENDER, np.zeros(5), render.IMAGE_SIZE)
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
        "poses": n_poses,
        "seed": seed,
        "one_way": one_way,
    }
    K = render.K_RENDER
    write_atomic(
        out / "camera_info.yaml",
        f"distortion_model: plumb_bob\nwidth: {render.IMAGE_SIZE[0]}\nheight: {render.IMAGE_SIZE[1]}\n"
        f"K: {json.dumps(K.reshape(-1).tolist())}\nD: [0, 0, 0, 0, 0]\n",
        force=True,
    )
    write_atomic(truth_path, json.dumps(truth, indent=2) + "\n", force=True)
    return {"out": str(out), "poses": n_poses, "seed": seed, "truth": str(truth_path), "box": truth["box"]}
