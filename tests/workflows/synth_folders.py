"""Rendered synthetic sessions shared by the capture tests: each scenario is rendered once per process.

``rendered(tmp_path_factory, scenario)`` returns the folder ``calibctl synth`` wrote (seeded, so the
same files every run). Tests must not write into it: copy it first.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.workflows.synth.synth import run_synth

SEED = 1
SIZES = {"video": (320, 240)}  # the video path only needs frames; 320x240 renders in 2/3 of the time
_CACHE: dict[str, Path] = {}


def rendered(factory: pytest.TempPathFactory, scenario: str) -> Path:
    """The folder of a rendered scenario (12 views at 640x480; the video: 8 key poses at 320x240)."""
    if scenario not in _CACHE:
        out = factory.mktemp(f"synth-{scenario}") / scenario
        run_synth(out, scenario, seed=SEED, image_size=SIZES.get(scenario, (640, 480)))
        _CACHE[scenario] = out
    return _CACHE[scenario]


# The fisheye station of the capture gauge: a 150 deg circular equidistant lens at 640x480 (f 177 px).
# Wide enough that a k1k2 lens fitted to its session misplaces the fixture board by far more than the
# gauge's 1 %, narrow enough that the detector finds the board in every view (OpenCV 4.10 and 5.0).
FISHEYE_FOV_DEG = 150.0
FISHEYE_FIXTURE_M = 0.150  # camera to board centre, on the optical axis
_FISHEYE: dict[str, tuple[Path, Path]] = {}


def fisheye_gauge_folders(factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(session folder, fixture folder) rendered through the SAME fisheye camera, once per process.

    The session is ``calibctl synth --fisheye 150`` (10 views, seed 1); the fixture is 4 pictures of the
    board centred on the axis at FISHEYE_FIXTURE_M, tilted 25 deg toward four directions.
    """
    if "folders" not in _FISHEYE:
        import cv2
        import numpy as np

        from calibctl.core.synth.fisheye import FisheyeCamera
        from calibctl.core.synth.pinhole import render_view
        from calibctl.core.synth.scenes import tilt_rotation
        from calibctl.workflows.synth.synth import default_board

        root = factory.mktemp("fisheye-gauge")
        run_synth(root / "session", "good", seed=SEED, views=10, fisheye_fov_deg=FISHEYE_FOV_DEG)
        camera = FisheyeCamera.from_fov((640, 480), FISHEYE_FOV_DEG)  # as run_synth's
        board = default_board()
        fixture = root / "fixture"
        fixture.mkdir()
        rng = np.random.default_rng(7)
        dark = camera.outside_circle()
        centre_board = board.object_points().mean(axis=0)
        for i in range(4):
            T = np.eye(4)
            T[:3, :3] = tilt_rotation(np.deg2rad(25.0), np.pi / 2 * i + 0.3, 0.1 * i)
            T[:3, 3] = [0.0, 0.0, FISHEYE_FIXTURE_M] - T[:3, :3] @ centre_board
            img = render_view(camera, board, T, rng)
            img[dark] = np.minimum(img[dark], 4)  # no light outside the image circle, as run_synth renders
            cv2.imwrite(str(fixture / f"fixture{i:02d}.png"), img)
        _FISHEYE["folders"] = (root / "session", fixture)
    return _FISHEYE["folders"]
