"""`calibctl check` on real photos (opencv-left-right): calibrate the left camera, re-test it on its own
images (pass) and on the right camera's (fail), and compare with a plain OpenCV re-projection."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.datasets import LEFT_RIGHT, require_datasets

RUNNER = CliRunner()


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> str:
    require_datasets()
    url = f"sqlite:///{tmp_path_factory.mktemp('real-check') / 'calibctl.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("LR", square_mm=25.0))
    done = invoke(
        url, "calibrate", "--serial", "LEFT", "--board", "LR", "--source", f"{LEFT_RIGHT}/left*.jpg"
    )
    assert done.exit_code == 0, done.output
    return url


def _plain_opencv_rms(paths: list[Path], K: np.ndarray, D: np.ndarray) -> dict[str, float]:
    """findChessboardCorners + cornerSubPix + solvePnP with the stored model, as OpenCV's tutorial does it."""
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
    out = {}
    for path in paths:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found, corners = cv2.findChessboardCorners(gray, (9, 6))
        if not found:
            continue
        corners = cv2.cornerSubPix(
            gray, corners, (11, 11), (-1, -1), (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
        )
        _, rvec, tvec = cv2.solvePnP(obj, corners, K, D)
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, D)
        residuals = corners.reshape(-1, 2) - proj.reshape(-1, 2)
        out[path.name] = float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))
    return out


def test_left_passes_on_its_own_images_and_the_right_camera_fails(db: str) -> None:
    same = invoke(db, "check", "LEFT", "--source", f"{LEFT_RIGHT}/left*.jpg", "--json")
    assert same.exit_code == 0, same.output
    other = invoke(db, "check", "LEFT", "--source", f"{LEFT_RIGHT}/right*.jpg", "--json")
    assert other.exit_code == 1, other.output
    event = json.loads(other.stdout)
    assert not event["passed"] and event["reasons"]
    assert event["regions"][0]["ratio"] > event["regions"][0]["limit"]


def test_the_residuals_agree_with_a_plain_opencv_reprojection(db: str) -> None:
    with Store.open(db) as store:
        art = store.get_artifact("LEFT")
    done = invoke(db, "check", "LEFT", "--source", f"{LEFT_RIGHT}/right*.jpg", "--json")
    event = json.loads(done.stdout)
    ours = dict(zip(event["views"], event["view_rms_px"], strict=True))
    plain = _plain_opencv_rms(
        sorted(LEFT_RIGHT.glob("right*.jpg")), np.array(art.camera_matrix), np.array(art.dist_coeffs)
    )
    common = sorted(set(ours) & set(plain))
    assert len(common) >= 10
    diffs = np.array([ours[n] - plain[n] for n in common])
    # Same model, same views: per-view RMS within 0.05 px (the detectors refine corners differently).
    assert np.median(np.abs(diffs)) < 0.05, dict(zip(common, diffs, strict=True))
