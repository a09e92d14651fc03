"""A single camera gets a Kalibr camchain and an mrcal .cameramodel too (`calibctl export --format
kalibr|mrcal`)."""

from __future__ import annotations

import ast

import cv2
import numpy as np
import pytest
import yaml

from calibctl.errors import InputError
from calibctl.workflows.exports import formats, trace_header
from tests.artifacts.factories import calibration


def test_kalibr_of_one_camera_is_cam0_with_overlaps_and_a_legal_topic():
    art = calibration()
    text = formats.render(art, "kalibr")
    assert trace_header.read(text).ref == "CAM-0001@1" and trace_header.read(text).intact
    cam = yaml.safe_load(text)["cam0"]
    assert cam["intrinsics"] == [800.0, 800.0, 320.0, 240.0] and cam["distortion_coeffs"] == [
        -0.2814,
        0.0977,
        0.0,
        0.0,
    ]
    assert (cam["distortion_model"], cam["cam_overlaps"], cam["rostopic"]) == (
        "radtan",
        [],
        "/cam_0001/image_raw",
    )


def test_mrcal_of_one_camera_projects_as_opencv():
    art = calibration()
    model = ast.literal_eval(formats.render(art, "mrcal"))  # what mrcal's reader does with the text
    assert model["lensmodel"] == "LENSMODEL_OPENCV5" and model["extrinsics"] == [0.0] * 6
    fx, fy, cx, cy, *dist = model["intrinsics"]
    K = np.array(art.camera_matrix)
    assert (fx, fy, cx, cy) == (K[0, 0], K[1, 1], K[0, 2], K[1, 2]) and dist == art.dist_coeffs
    assert model["imagersize"] == list(art.image_size)
    X = np.array([[0.1, -0.05, 1.0]])
    assert np.allclose(
        cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, np.array(dist))[0].ravel(),
        cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, np.array(art.dist_coeffs))[0].ravel(),
    )


def test_a_fisheye_has_no_mrcal_model_and_says_why():
    art = calibration()
    fisheye = art.model_copy(
        update={
            "model": art.model.model_copy(update={"name": "fisheye"}),
            "dist_coeffs": [0.01, -0.002, 0.0005, 0.0],
        }
    ).sealed()
    with pytest.raises(InputError, match="mrcal has no Kannala-Brandt"):
        formats.render(fisheye, "mrcal")
    assert yaml.safe_load(formats.render(fisheye, "kalibr"))["cam0"]["distortion_model"] == "equidistant"


def _with_region():
    hull = [(40.0, 30.0), (600.0, 35.5), (610.0, 450.0), (35.0, 440.0)]
    return calibration().model_copy(update={"observed_region_px": hull}).sealed(), hull


def test_mrcal_of_one_camera_carries_the_observed_corners_hull_as_its_valid_region():
    art, hull = _with_region()
    model = ast.literal_eval(formats.render(art, "mrcal"))
    assert model["valid_intrinsics_region"] == [list(p) for p in [*hull, hull[0]]]  # closed, as mrcal wants
    assert "valid_intrinsics_region" not in ast.literal_eval(formats.render(calibration(), "mrcal"))


def test_debian_mrcal_reads_the_valid_region(tmp_path):
    """mrcal's own reader (Debian's python3-mrcal, `make test-consumers`) takes the region as written."""
    import subprocess
    from pathlib import Path

    if not Path("/usr/bin/python3").exists():
        pytest.skip("no /usr/bin/python3: Debian's python3-mrcal is not installed (make test-consumers)")
    art, hull = _with_region()
    path = tmp_path / "cam.cameramodel"
    path.write_text(formats.render(art, "mrcal"))
    code = "import sys, mrcal; print(mrcal.cameramodel(sys.argv[1]).valid_intrinsics_region().tolist())"
    run = subprocess.run(["/usr/bin/python3", "-c", code, str(path)], capture_output=True, text=True)
    if "No module named 'mrcal'" in run.stderr:
        pytest.skip("Debian's python3-mrcal is not installed (make test-consumers)")
    assert run.returncode == 0, run.stderr
    assert ast.literal_eval(run.stdout) == [list(p) for p in [*hull, hull[0]]]
