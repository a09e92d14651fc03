"""Real photos (OpenCV's 13 left stereo images): calibrate, export in every format, lint them back, and read
the exports with plain OpenCV / PyYAML the way a robot would."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from calibctl.cli.main import app
from tests.cli.real_left import BOARD_9X6_M, PLAIN_FLAGS, calibrated_left_store, plain_opencv_corners
from tests.datasets import LEFT_RIGHT

SERIAL = "LEFT-01"
PLAIN_FX_TOLERANCE = 0.01  # calibctl's detector differs from the plain recipe; both must describe one camera


@pytest.fixture(scope="module")
def exports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("real-export")
    url = calibrated_left_store(root, SERIAL)
    runner = CliRunner()
    out = {}
    for fmt in ("json", "yaml", "ros", "opencv"):
        out[fmt] = root / f"{SERIAL}.{fmt}.{'json' if fmt == 'json' else 'yaml'}"
        assert (
            runner.invoke(app, ["--db", url, "export", SERIAL, "-f", fmt, "-o", str(out[fmt])]).exit_code == 0
        )
    return out


def plain_opencv_fx(images: list[Path]) -> float:
    """cv2.calibrateCamera on corners from findChessboardCorners + cornerSubPix, calibctl's default flags."""
    points = plain_opencv_corners(images)
    _, K, _, _, _ = cv2.calibrateCamera(
        [BOARD_9X6_M] * len(points), points, (640, 480), np.eye(3), None, flags=PLAIN_FLAGS
    )
    return float(K[0, 0])


def test_every_export_of_a_real_calibration_passes_lint(exports):
    result = CliRunner().invoke(app, ["lint", *map(str, exports.values()), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert [r["kind"] for r in report["results"]] == ["calibctl", "calibctl", "ros", "opencv"]
    assert all(r["findings"] == [] for r in report["results"])


def test_robots_read_the_same_numbers_from_every_format(exports):
    art = json.loads(exports["json"].read_text())
    K = np.array(art["camera_matrix"])
    ros = yaml.safe_load(exports["ros"].read_text())
    np.testing.assert_array_equal(np.reshape(ros["camera_matrix"]["data"], (3, 3)), K)
    assert ros["distortion_coefficients"]["data"] == [*art["dist_coeffs"], 0.0][:5]
    assert ros["camera_name"] == "LEFT_01" and ros["distortion_model"] == "plumb_bob"
    fs = cv2.FileStorage(str(exports["opencv"]), cv2.FILE_STORAGE_READ)
    np.testing.assert_array_equal(fs.getNode("camera_matrix").mat(), K)
    assert fs.getNode("status").string() == "accepted"
    fs.release()
    # the same camera plain OpenCV finds on the same photos (within 1 %: the corner detectors differ)
    plain_fx = plain_opencv_fx(sorted(LEFT_RIGHT.glob("left*.jpg")))
    assert abs(K[0, 0] / plain_fx - 1) < PLAIN_FX_TOLERANCE, (K[0, 0], plain_fx)
