"""``calibctl synth --rig N``: synchronised photos of an N-camera rig (2-4) and its truth.

Layout of OUT::

    CAM0/CAM0_0000.png  CAM0/CAM0_0001.png ...   one folder per camera (camera 0 is the root)
    CAM1/CAM1_0000.png ...                        same frame number = taken together
    rig_truth.json

A camera that does not see the whole board in a frame gets no photo for that frame (so the frame
matching of ``calibctl rig solve-folders`` has gaps to deal with). ``rig_truth.json``::

    {"schema": "calibctl.synth.rig_truth/1", "generator": {"seed", "cameras", "calibctl_version", ...},
     "board": {...}, "root": "CAM0",
     "cameras": [{"name", "K", "dist", "image_size", "T_root_cam"}],   # K 3x3 px, T 4x4 metres
     "frames": [{"frame", "T_root_board", "seen_by": [names]}]}
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from calibctl import __version__
from calibctl.core.synth.rig import render_rig_frame, synthesize_rig
from calibctl.errors import InputError, UsageError
from calibctl.files import write_atomic
from calibctl.workflows.synth.synth import default_board

RIG_TRUTH_SCHEMA = "calibctl.synth.rig_truth/1"
RIG_TRUTH_FILE = "rig_truth.json"
DEFAULT_RIG_FRAMES = 14


@dataclass(frozen=True)
class RigSynthResult:
    out_dir: Path
    cameras: tuple[str, ...]
    n_frames: int
    photos_per_camera: tuple[int, ...]
    truth_path: Path

    def as_json(self) -> dict[str, object]:
        return {
            "out_dir": str(self.out_dir),
            "cameras": list(self.cameras),
            "n_frames": self.n_frames,
            "photos_per_camera": dict(zip(self.cameras, self.photos_per_camera, strict=True)),
            "truth": str(self.truth_path),
        }


def run_synth_rig(
    out: Path,
    n_cameras: int,
    seed: int = 0,
    frames: int | None = None,
    image_size: tuple[int, int] = (640, 480),
    baseline_mm: float | None = None,
    force: bool = False,
) -> RigSynthResult:
    """Render a seeded rig session into ``out`` (module docstring). Deterministic for the same arguments."""
    if not 2 <= n_cameras <= 4:
        raise UsageError(f"--rig takes 2 to 4 cameras, got {n_cameras}")
    n_frames = frames or DEFAULT_RIG_FRAMES
    if not 2 <= n_frames <= 200:
        raise UsageError(f"--views must be between 2 and 200 for a rig, got {n_frames}")
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not force)):
        raise InputError(
            f"{out} exists and is not an empty folder", "choose an empty or new folder, or pass --force"
        )
    board = default_board()
    rng = np.random.default_rng(seed)
    baselines = None if baseline_mm is None else (baseline_mm / 1e3,) * (n_cameras - 1)
    try:
        truth = synthesize_rig(n_cameras, board, n_frames, rng, image_size, baselines, min_cameras=2)
    except ValueError as exc:
        raise UsageError(
            f"cannot stage a {n_cameras}-camera rig at {image_size[0]}x{image_size[1]}: {exc}"
        ) from exc
    counts = [0] * n_cameras
    frame_records = []
    for name in truth.names:
        (out / name).mkdir(parents=True, exist_ok=True)
    for f in range(n_frames):
        images = render_rig_frame(truth, board, f, rng)
        seen = []
        for c, image in enumerate(images):
            if image is None:
                continue
            path = out / truth.names[c] / f"{truth.names[c]}_{f:04d}.png"
            ok, png = cv2.imencode(".png", image)
            if not ok:
                raise InputError(f"cannot encode {path}")
            write_atomic(path, png.tobytes(), force=True)
            counts[c] += 1
            seen.append(truth.names[c])
        frame_records.append({"frame": f, "T_root_board": truth.T_root_board[f].tolist(), "seen_by": seen})
    doc = {
        "schema": RIG_TRUTH_SCHEMA,
        "generator": {
            "seed": seed,
            "cameras": n_cameras,
            "calibctl_version": __version__,
            "opencv_version": cv2.__version__,
        },
        "board": board.to_dict(),
        "root": truth.names[0],
        "cameras": [
            {
                "name": n,
                "K": cam.K.tolist(),
                "dist": cam.dist.tolist(),
                "image_size": list(cam.image_size),
                "T_root_cam": T.tolist(),
            }
            for n, cam, T in zip(truth.names, truth.cameras, truth.T_root_cam, strict=True)
        ],
        "frames": frame_records,
    }
    truth_path = out / RIG_TRUTH_FILE
    write_atomic(truth_path, json.dumps(doc, indent=1) + "\n", force=True)
    return RigSynthResult(out, truth.names, n_frames, tuple(counts), truth_path)
