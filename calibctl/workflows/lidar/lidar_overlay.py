"""LiDAR points drawn over each image through the solved T: the check a person does by eye.

Every point of each accepted pose's sweep is moved into the camera (T_cam_lidar = T_lidar_cam^-1),
kept when in front of the lens (within 80 degrees of the axis for a fisheye), projected through the
camera's own lens model and drawn as a dot coloured by range (near red, far blue, OpenCV's JET map over
0.5-8 m). On a good T the board's dots sit on the board's outline in the image.
"""

from __future__ import annotations

import base64
import hashlib
from pathlib import Path

import cv2
import numpy as np

from calibctl import bounded
from calibctl.artifacts.lidar import LidarEdgeResult
from calibctl.config import Settings
from calibctl.core.extrinsics import se3
from calibctl.core.intrinsics.solve import is_fisheye, project_points
from calibctl.errors import CalibctlError, InputError
from calibctl.files import file_errors, write_atomic
from calibctl.workflows.lidar.camera import Lens, lens_from_store
from calibctl.workflows.lidar.scans import read_scan

NEAR_M, FAR_M = 0.5, 8.0
REPORT_WIDTH_PX = 800
MAX_OFF_AXIS_DEG = 80.0


def overlay_image(
    image_bgr: np.ndarray, points_lidar_m: np.ndarray, T_lidar_cam: np.ndarray, lens: Lens
) -> np.ndarray:
    """(H, W, 3) uint8 image with the (N, 3) LiDAR points drawn over it; the input is not changed."""
    T_cam_lidar = se3.invert(T_lidar_cam)
    p = points_lidar_m @ T_cam_lidar[:3, :3].T + T_cam_lidar[:3, 3]
    r = np.linalg.norm(p, axis=1)
    ahead = p[:, 2] > 0.1
    if is_fisheye(lens.model):
        ahead &= p[:, 2] > r * np.cos(np.radians(MAX_OFF_AXIS_DEG))
    p, r = p[ahead], r[ahead]
    out = image_bgr.copy()
    if not len(p):
        return out
    px = project_points(p, np.zeros(3), np.zeros(3), lens.camera_matrix, lens.dist_coeffs, lens.model)
    h, w = out.shape[:2]
    inside = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    if not inside.any():
        return out
    shade = np.clip((r[inside] - NEAR_M) / (FAR_M - NEAR_M) * 255, 0, 255).astype(np.uint8)
    colours = cv2.applyColorMap(255 - shade.reshape(-1, 1), cv2.COLORMAP_JET).reshape(-1, 3)
    for (u, v), c in zip(px[inside], colours, strict=True):
        cv2.circle(out, (round(float(u)), round(float(v))), 2, tuple(int(x) for x in c), -1, cv2.LINE_AA)
    return out


def write_overlays(
    out_dir: Path,
    pairs: list[tuple[Path, Path]],
    T_lidar_cam: np.ndarray,
    lens: Lens,
    scale_to_m: float = 1.0,
    force: bool = False,
) -> list[str]:
    """One ``<image stem>_lidar.png`` per (image, scan) pair in ``out_dir``; the paths written."""
    with file_errors("create", out_dir):
        out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for image, scan in pairs:
        with file_errors("read image", image):
            data = image.read_bytes()
        bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:  # the solve read it a moment ago; it changed since
            raise InputError(f"{image} is not a readable image", "re-run with the images left in place")
        drawn = overlay_image(bgr, read_scan(scan, scale_to_m).points_m, T_lidar_cam, lens)
        ok, png = cv2.imencode(".png", drawn)
        target = out_dir / f"{image.stem}_lidar.png"
        write_atomic(target, png.tobytes(), force=force)
        written.append(str(target))
    return written


def report_overlay(settings: Settings, ev: LidarEdgeResult) -> tuple[str | None, str]:
    """The stored edge's sweep over its image for the rig report: (a ``data:image/jpeg`` URI, what it
    shows) or (None, why it cannot be drawn). The images and sweeps are not in the store: the files the
    solve read are used only when they are still where they were, byte for byte (sha256)."""
    src, t = ev.overlay, ev.transform
    if ev.status != "accepted" or src is None or t is None:
        return None, "not drawn: no accepted transform to draw through"
    data: dict[str, bytes] = {}
    for kind, path, sha in (
        ("image", src.image_path, src.image_sha256),
        ("scan", src.scan_path, src.scan_sha256),
    ):
        p = Path(path)
        if not p.is_file():
            return None, (
                f"not drawn: images and scans are not in the store, and the {kind} the solve read "
                f"({path}) is not there any more"
            )
        try:
            bounded.check_size(p, f"read {kind}")
            data[kind] = p.read_bytes()
        except CalibctlError as exc:
            return None, f"not drawn: {exc.message}"
        except OSError as exc:
            return None, f"not drawn: {path}: {exc.strerror or exc}"
        if hashlib.sha256(data[kind]).hexdigest() != sha:
            return None, f"not drawn: the {kind} {path} changed since the solve (sha256 differs)"
    serial, _, version = ev.camera.rpartition("@")
    try:
        lens = lens_from_store(settings, serial, int(version))
        cloud = read_scan(Path(src.scan_path), src.scan_scale_to_m)
    except (CalibctlError, ValueError) as exc:
        return None, f"not drawn: {getattr(exc, 'message', exc)}"
    bgr = cv2.imdecode(np.frombuffer(data["image"], np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        return None, f"not drawn: {src.image_path} is not a readable image"
    drawn = overlay_image(bgr, cloud.points_m, np.array(t.T_lidar_cam), lens)
    scale = min(1.0, REPORT_WIDTH_PX / drawn.shape[1])
    small = cv2.resize(drawn, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else drawn
    ok, jpg = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, 85])
    uri = "data:image/jpeg;base64," + base64.b64encode(jpg.tobytes()).decode("ascii")
    return uri, (
        f"{len(cloud.points_m)} points of {Path(src.scan_path).name} over {Path(src.image_path).name} "
        f"through the stored T_{ev.parent_frame}_cam (dots by range: near red, far blue)"
    )
