"""OpenCV's 13 left images (../shared/datasets/opencv-left-right) calibrated into a fresh store, and the
plain OpenCV recipe on the same files, for the CLI tests that compare calibctl's output with it."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.datasets import LEFT_RIGHT, require_datasets

BOARD_9X6_M = np.zeros((54, 3), np.float32)
BOARD_9X6_M[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
PLAIN_FLAGS = (
    cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_ASPECT_RATIO
)  # calibctl's default


def calibrated_left_store(root: Path, serial: str) -> str:
    """Copy the left images under ``root``, register a measured 25 mm board A17, calibrate; the store URL."""
    require_datasets()
    left = root / "left"
    left.mkdir()
    for path in sorted(LEFT_RIGHT.glob("left*.jpg")):
        shutil.copy(path, left / path.name)
    url = f"sqlite:///{root / 'store.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    done = CliRunner().invoke(
        app, ["--db", url, "calibrate", "--serial", serial, "--board", "A17", "--source", str(left)]
    )
    assert done.exit_code == 0, done.output
    return url


def plain_opencv_corners(images: list[Path]) -> list[np.ndarray]:
    """findChessboardCorners + cornerSubPix, the plain OpenCV recipe: one (54, 1, 2) float32 per image."""
    points = []
    for path in images:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        ok, corners = cv2.findChessboardCorners(
            gray, (9, 6), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        )
        assert ok, path
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
        points.append(cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria))
    return points
