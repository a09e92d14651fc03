"""calibctl report on real photos (OpenCV's 13 left images): written, the same bytes after the images are
pruned, its coverage checked against a plain OpenCV recipe on the same files; bad input exits 2."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from tests.cli.real_left import BOARD_9X6_M, PLAIN_FLAGS, calibrated_left_store, plain_opencv_corners

SERIAL = "LEFT-01"
EDGE_TOLERANCE_PX = (
    2.0  # calibctl's sub-pixel refinement differs from the plain recipe by a fraction of a pixel
)


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("real-report")
    url = calibrated_left_store(root, SERIAL)
    return {"url": url, "root": root, "images": sorted((root / "left").glob("*.jpg"))}


def run(store: dict, *args: str):
    return CliRunner().invoke(app, ["--db", store["url"], *args])


def plain_opencv(images: list[Path]) -> tuple[np.ndarray, float]:
    """Every corner of the plain OpenCV recipe, and cv2.calibrateCamera's RMS on them."""
    points = plain_opencv_corners(images)
    rms, *_ = cv2.calibrateCamera(
        [BOARD_9X6_M] * len(points), points, (640, 480), np.eye(3), None, flags=PLAIN_FLAGS
    )
    return np.concatenate(points).reshape(-1, 2), float(rms)


def test_the_real_report_agrees_with_plain_opencv_and_survives_pruning(store):
    out = store["root"] / "report.html"
    result = run(store, "report", SERIAL, "-o", str(out), "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["bytes"] == out.stat().st_size < 1_000_000
    html = out.read_text(encoding="utf-8")
    shown = dict(re.findall(r'data-key="([^"]+)">([^<]*)<', html))
    corners, plain_rms = plain_opencv(store["images"])
    plain_gaps = {
        "left": corners[:, 0].min(),
        "right": 639 - corners[:, 0].max(),
        "top": corners[:, 1].min(),
        "bottom": 479 - corners[:, 1].max(),
    }
    for side, gap in plain_gaps.items():
        assert abs(float(shown[f"gap_{side}"]) - gap) <= EDGE_TOLERANCE_PX, side
    # the same files through the plain recipe fit worse (no corner rule, coarser refinement), never better
    assert float(shown["rms_px"]) <= plain_rms
    assert int(shown["empty_cells"]) > 0  # the finding: the corners never reach the outer band
    assert shown["active"] == "yes"  # the page says whether this is the version a robot loads now
    # prune every image: the report is drawn from stored corners, so the bytes do not change
    pruned = run(store, "prune", "--now", "2100-01-01T00:00:00Z", "--json")
    assert pruned.exit_code == 0 and json.loads(pruned.stdout)["pruned"] > 0, pruned.output
    again = store["root"] / "again.html"
    assert run(store, "report", f"{SERIAL}@1", "-o", str(again)).exit_code == 0
    assert again.read_bytes() == out.read_bytes()


def test_an_unknown_serial_or_version_exits_2_naming_it(store):
    result = run(store, "report", "NO-SUCH-CAM")
    assert result.exit_code == 2 and "unknown serial 'NO-SUCH-CAM'" in result.stderr
    result = run(store, "report", f"{SERIAL}@9")
    assert result.exit_code == 2 and "has no version 9" in result.stderr


def test_an_existing_output_is_kept_without_force(store):
    out = store["root"] / "kept.html"
    out.write_text("mine", encoding="utf-8")
    result = run(store, "report", SERIAL, "-o", str(out))
    assert result.exit_code == 2 and "already exists" in result.stderr and "--force" in result.stderr
    assert out.read_text(encoding="utf-8") == "mine"
    assert run(store, "report", SERIAL, "-o", str(out), "--force").exit_code == 0
    assert out.read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


def test_an_output_folder_that_does_not_exist_exits_2(store):
    result = run(store, "report", SERIAL, "-o", str(store["root"] / "nowhere" / "r.html"))
    assert result.exit_code == 2 and "does not exist" in result.stderr
