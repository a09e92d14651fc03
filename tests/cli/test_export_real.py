"""Real photos (OpenCV's 13 left stereo images): calibrate, export in every format, lint them back, and read
the exports with plain OpenCV / PyYAML the way a robot would."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.datasets import LEFT_RIGHT, require_datasets

SERIAL = "LEFT-01"
PLAIN_FX_TOLERANCE = 0.01  # calibctl's detector differs from the plain recipe; both must describe one camera


@pytest.fixture(scope="module")
def exports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    require_datasets()
    root = tmp_path_factory.mktemp("real-export")
    left = root / "left"
    left.mkdir()
    for path in sorted(LEFT_RIGHT.glob("left*.jpg")):
        shutil.copy(path, left / path.name)
    url = f"sqlite:///{root / 'store.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    runner = CliRunner()
    done = runner.invoke(app, ["--db", url, "calibrate", "--serial", SERIAL, "--board", "A17", "--source", str(left)])
    assert done.exit_code == 0, done.output
    out = {}
    for fmt in ("json", "yaml", "ros", "opencv"):
        out[fmt] = root / f"{SERIAL}.{fmt}.{'json' if fmt == 'json' else 'yaml'}"
        assert runner.invoke(app, ["--db", url, "export", SERIAL, "-f", fmt, "-o", str(out[fmt])]).exit_code == 0
    return out


def plain_opencv_fx(images: list[Path]) -> float:
    """cv2.calibrateCamera on corners from findChessboardCorners + cornerSubPix, calibctl's default flags."""
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
    object_points, image_points = [], []
    for path in images:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        ok, corners = cv2.findChessboardCorners(gray, (9, 6), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        assert ok, path
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
        image_points.append(cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria))
        object_points.append(obj)
    flags = cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_ASPECT_RATIO
    _, K, _, _, _ = cv2.calibrateCamera(object_points, image_points, (640, 480), np.eye(3), None, flags=flags)
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
