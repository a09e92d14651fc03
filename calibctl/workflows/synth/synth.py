"""``calibctl synth``: write a synthetic session (PNG views or an MJPG video) and its truth.json.

The output folder holds ``view-000.png`` ... (still scenarios) or ``video.avi`` (scenario ``video``),
plus ``truth.json``::

    {"schema": "calibctl.synth.truth/1",
     "generator": {"scenario", "seed", "calibctl_version", "opencv_version"},
     "camera": {"model", "K", "dist", "image_size"[, "fov_deg", "image_circle_px"]},
                # K: 3x3 px; dist: k1 k2 p1 p2 k3 (pinhole) or k1..k4 (fisheye); [W, H]
     "board": {"kind", "cols", "rows", "square_size_m", ...},
     "views": [{"file" | "frame", "rvec", "tvec", "T_cam_board", "corners_px", "tilt_deg",
                "direction_deg", "still"?, "key_pose"?}, ...],
     "video": {"file", "fps", "n_frames"}?}

Corner ids are row-major (``corners_px[i]`` is model point i). ``T_cam_board`` maps board points
(metres) into the camera frame; rvec/tvec are its OpenCV form.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from calibctl import __version__, bounded
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.synth.fisheye import FisheyeCamera, default_fisheye_distance_m, fisheye_poses
from calibctl.core.synth.pinhole import (
    Photometry,
    PinholeCamera,
    render_background,
    render_view,
    rvec_tvec,
    true_corners_px,
)
from calibctl.core.synth.scenes import SCENARIOS, scenario_poses, video_plan
from calibctl.errors import AlreadyExistsError, InputError, UsageError
from calibctl.files import existing_target, file_errors, write_atomic

TRUTH_SCHEMA = "calibctl.synth.truth/1"
DEFAULT_VIEWS = 12
DEFAULT_VIDEO_KEYS = 8
VIDEO_FPS = 10.0
VIDEO_FILE = "video.avi"
TRUTH_FILE = "truth.json"
PATTERNS = ("chessboard", "charuco", "aprilgrid")


@dataclass(frozen=True)
class SynthResult:
    out_dir: Path
    scenario: str
    image_size: tuple[int, int]
    files: list[str]
    truth_path: Path
    n_views: int

    def as_json(self) -> dict[str, object]:
        return {
            "out_dir": str(self.out_dir),
            "scenario": self.scenario,
            "image_size": list(self.image_size),
            "files": self.files,
            "truth": str(self.truth_path),
            "n_views": self.n_views,
        }


def default_board(pattern: str = "chessboard") -> BoardSpec:
    """9x6 inner corners, 25 mm squares (the seed's board); ChArUco: 10x7 squares, 18 mm DICT_4X4_50 markers;
    AprilGrid: Kalibr's 6x6 36h11 tags, scaled to 30 mm tags (tagSpacing 0.3)."""
    if pattern == "aprilgrid":
        return BoardSpec.aprilgrid(6, 6, 0.03, 0.3)
    if pattern == "charuco":
        return BoardSpec.charuco(10, 7, 0.025, 0.018, "DICT_4X4_50")
    return BoardSpec.chessboard(9, 6, 0.025)


def parse_size(text: str) -> tuple[int, int]:
    """'640x480' -> (640, 480)."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise UsageError(f"--size must look like 640x480, got {text!r}")
    width, height = int(parts[0]), int(parts[1])
    if not (160 <= width <= 8192 and 120 <= height <= 8192):
        raise UsageError(f"--size {width}x{height} is out of range (160x120 .. 8192x8192)")
    return width, height


def _prepare_out(out: Path, force: bool) -> None:
    if out.exists() and not out.is_dir():
        raise InputError(f"{out} exists and is not a folder", "choose another OUT")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise AlreadyExistsError(f"{out} is not empty", "choose an empty or new folder, or pass --force")
        olds = list(out.glob("view-*.png")) + [out / VIDEO_FILE, out / TRUTH_FILE]
        ours = [
            old for old in olds if existing_target(old) is not None
        ]  # a symlink/FIFO there: refused, kept
        with file_errors("clear", out):
            for old in ours:
                old.unlink()
    with file_errors("create", out):
        out.mkdir(parents=True, exist_ok=True)


def _view_record(camera: PinholeCamera | FisheyeCamera, board: BoardSpec, T: np.ndarray) -> dict[str, object]:
    rvec, tvec = rvec_tvec(T)
    normal = T[:3, 2]
    facing = -normal if normal[2] > 0 else normal
    return {
        "rvec": rvec.tolist(),
        "tvec": tvec.tolist(),
        "T_cam_board": T.tolist(),
        "corners_px": true_corners_px(camera, board, T).tolist(),
        "tilt_deg": math.degrees(math.acos(min(1.0, abs(float(normal[2]))))),
        "direction_deg": math.degrees(math.atan2(facing[1], facing[0])) % 360.0,
    }


def run_synth(
    out: Path,
    scenario: str = "good",
    seed: int = 0,
    views: int | None = None,
    image_size: tuple[int, int] = (640, 480),
    pattern: str = "chessboard",
    force: bool = False,
    fisheye_fov_deg: float | None = None,
    circular: bool = True,
) -> SynthResult:
    """Render one scenario into ``out``. Deterministic for a given (scenario, seed, views, size, pattern).

    ``fisheye_fov_deg``: render through an equidistant fisheye of that field of view instead (scenario
    good only; 60-190 deg), with an image circle (``circular``) or full-frame.
    """
    if fisheye_fov_deg is not None:
        return _run_fisheye(out, scenario, seed, views, image_size, pattern, force, fisheye_fov_deg, circular)
    if scenario not in SCENARIOS:
        raise UsageError(f"unknown scenario {scenario!r}", f"choose one of {', '.join(SCENARIOS)}")
    if pattern not in PATTERNS:
        raise UsageError(f"unknown pattern {pattern!r}", f"choose one of {', '.join(PATTERNS)}")
    if views is not None and not 1 <= views <= 500:
        raise UsageError(f"--views must be between 1 and 500, got {views}")
    camera = PinholeCamera.seed_reference(image_size)
    board = default_board(pattern)
    rng = np.random.default_rng(seed)
    try:
        if scenario == "video":
            plan = video_plan(camera, board, views or DEFAULT_VIDEO_KEYS, rng)
            poses = plan.poses
        else:
            poses = scenario_poses(scenario, camera, board, views or DEFAULT_VIEWS, rng)
    except ValueError as exc:
        raise UsageError(
            f"cannot stage scenario {scenario!r} at {image_size[0]}x{image_size[1]}: {exc}"
        ) from exc
    _prepare_out(out, force)
    background = render_background(image_size, rng)
    records: list[dict[str, object]] = []
    files: list[str] = []
    writer = None
    if scenario == "video":
        writer = cv2.VideoWriter(
            str(out / VIDEO_FILE), cv2.VideoWriter.fourcc(*"MJPG"), VIDEO_FPS, image_size, False
        )
        if not writer.isOpened():
            raise InputError(
                f"cannot write an MJPG video to {out / VIDEO_FILE}", "is OpenCV built with video I/O?"
            )
        files.append(VIDEO_FILE)
    photometry = Photometry.random(rng)
    try:
        for i, T in enumerate(poses):
            if writer is None:
                photometry = Photometry.random(rng)
            img = render_view(camera, board, T, rng, photometry, background)
            record = _view_record(camera, board, T)
            if writer is not None:
                writer.write(img)
                record = {"frame": i, "still": plan.still[i], "key_pose": plan.key_index[i], **record}
            else:
                name = f"view-{i:03d}.png"
                write_atomic(out / name, cv2.imencode(".png", img)[1].tobytes(), force=True)
                files.append(name)
                record = {"file": name, **record}
            records.append(record)
    finally:
        if writer is not None:
            writer.release()
    truth: dict[str, object] = {
        "schema": TRUTH_SCHEMA,
        "generator": {
            "scenario": scenario,
            "seed": seed,
            "calibctl_version": __version__,
            "opencv_version": cv2.__version__,
        },
        "camera": {
            "model": "pinhole + Brown-Conrady (k1, k2, p1, p2, k3)",
            "K": camera.K.tolist(),
            "dist": camera.dist.tolist(),
            "image_size": list(image_size),
        },
        "board": board.to_dict(),
        "views": records,
    }
    if writer is not None:
        truth["video"] = {"file": VIDEO_FILE, "fps": VIDEO_FPS, "n_frames": len(records)}
    truth_path = out / TRUTH_FILE
    write_atomic(truth_path, json.dumps(truth, indent=1) + "\n", force=True)
    return SynthResult(out, scenario, image_size, files, truth_path, len(records))


def load_truth(path: Path) -> dict[str, object]:
    """Read a truth.json written by ``run_synth``."""
    data = bounded.load_file(Path(path))
    if not isinstance(data, dict) or data.get("schema") != TRUTH_SCHEMA:
        raise InputError(f"{path} is not a calibctl synth truth file")
    return data


def _run_fisheye(
    out: Path,
    scenario: str,
    seed: int,
    views: int | None,
    image_size: tuple[int, int],
    pattern: str,
    force: bool,
    fov_deg: float,
    circular: bool,
) -> SynthResult:
    """``calibctl synth --fisheye FOV``: PNG views through an equidistant lens, and truth.json."""
    if scenario != "good":
        raise UsageError(f"--fisheye renders the good scenario only, not {scenario!r}", "drop --scenario")
    if not 60.0 <= fov_deg <= 190.0:
        raise UsageError(f"--fisheye field of view must be 60-190 deg, got {fov_deg:g}")
    if pattern not in PATTERNS:
        raise UsageError(f"unknown pattern {pattern!r}", f"choose one of {', '.join(PATTERNS)}")
    if pattern == "aprilgrid":  # its frame faces the other way (Kalibr's); the fisheye poses are not turned
        raise UsageError(
            "--fisheye renders chessboards and ChArUco boards", "drop --fisheye or --pattern aprilgrid"
        )
    camera = FisheyeCamera.from_fov(image_size, fov_deg, circular)
    board = default_board(pattern)
    rng = np.random.default_rng(seed)
    try:
        poses = fisheye_poses(
            camera,
            board.object_points(),
            views or DEFAULT_VIEWS,
            rng,
            default_fisheye_distance_m(camera, board.square_size_m),
            (15.0, 45.0),
            None,
            6.0,
        )
    except ValueError as exc:
        raise UsageError(
            f"cannot stage a {fov_deg:g} deg fisheye at {image_size[0]}x{image_size[1]}: {exc}"
        ) from exc
    _prepare_out(out, force)
    background = render_background(image_size, rng)
    dark = camera.outside_circle()
    records, files = [], []
    for i, T in enumerate(poses):
        img = render_view(camera, board, T, rng, Photometry.random(rng), background)
        img[dark] = np.minimum(img[dark], 4)  # no light reaches the sensor outside the image circle
        name = f"view-{i:03d}.png"
        write_atomic(out / name, cv2.imencode(".png", img)[1].tobytes(), force=True)
        files.append(name)
        records.append({"file": name, **_view_record(camera, board, T)})
    truth = {
        "schema": TRUTH_SCHEMA,
        "generator": {
            "scenario": scenario,
            "seed": seed,
            "calibctl_version": __version__,
            "opencv_version": cv2.__version__,
        },
        "camera": {
            "model": "fisheye (equidistant Kannala-Brandt, k1..k4; cv2.fisheye, ROS equidistant)",
            "K": camera.K.tolist(),
            "dist": camera.dist.tolist(),
            "image_size": list(image_size),
            "fov_deg": fov_deg,
            "image_circle_px": camera.circle_radius_px,
        },
        "board": board.to_dict(),
        "views": records,
    }
    truth_path = out / TRUTH_FILE
    write_atomic(truth_path, json.dumps(truth, indent=1) + "\n", force=True)
    return SynthResult(out, scenario, image_size, files, truth_path, len(records))
