"""The report's coverage map of a circular fisheye: the image circle the coverage gate recorded is drawn,
the cells outside it are marked not imaged (grey), and only cells inside it count as never reached; the
residuals, projection uncertainty and distortion curve go through the fisheye lens. A pinhole page has no
circle (its bytes are pinned by tests/workflows/report/test_report_workflow.py)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.core.capture.image_circle import ImageCircle, cells_inside_mask
from calibctl.store.repository import Store
from calibctl.workflows.report.report_html import COVERAGE_CELLS
from calibctl.workflows.synth.synth import run_synth
from tests.artifacts.factories import measured_board

RUNNER = CliRunner()
CIRCLE = (322.8, 237.4, 236.0)  # the render's truth, px


def shown(html: str) -> dict[str, str]:
    return dict(re.findall(r'data-key="([^"]+)">([^<]*)<', html))


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    root = tmp_path_factory.mktemp("fisheye-report")
    url = f"sqlite:///{root / 'r.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    run_synth(root / "r190", "good", seed=6, views=12, image_size=(640, 480), fisheye_fov_deg=190.0)
    result = RUNNER.invoke(
        app,
        [
            "--db",
            url,
            "calibrate",
            "--serial",
            "FE-0190",
            "--board",
            "A17",
            "--source",
            str(root / "r190"),
            "--model",
            "fisheye",
            "--image-circle",
            "322.8,237.4,236",
        ],
    )
    assert result.exit_code == 0, result.output
    run_synth(root / "pin", "good", seed=1, views=12, image_size=(640, 480))
    result = RUNNER.invoke(
        app, ["--db", url, "calibrate", "--serial", "PIN-1", "--board", "A17", "--source", str(root / "pin")]
    )
    assert result.exit_code in (0, 1), result.output
    return url, root


def test_a_circular_fisheye_report_draws_its_circle_and_greys_the_cells_outside(db: tuple[str, Path]) -> None:
    url, root = db
    out = root / "fe.html"
    assert RUNNER.invoke(app, ["--db", url, "report", "FE-0190", "-o", str(out)]).exit_code == 0
    html = out.read_text(encoding="utf-8")
    values = shown(html)
    imaged = cells_inside_mask(ImageCircle(*CIRCLE, source="given"), (640, 480), COVERAGE_CELLS)
    assert (
        "Image circle (given): centre (322.8, 237.4) px" in html
        and values["image_circle_radius_px"] == "236.0"
    )
    assert int(values["not_imaged_cells"]) == int((~imaged).sum()) > 0
    assert html.count('fill="#dddddd"') == int((~imaged).sum())  # one grey cell per cell outside the circle
    # the never-reached count is over the cells inside the circle only
    assert int(values["empty_cells"]) < int(imaged.sum())
    assert int(values["empty_cells"]) + int(values["not_imaged_cells"]) <= imaged.size
    # the circle itself: a closed polyline through (cx + r, cy) in the plot's coordinates
    assert re.search(r'<polyline points="[^"]*" fill="none" stroke="#555555"', html)
    # the rest of the page reads the fisheye lens (it exited 2 on the stored fisheye covariance before)
    assert (
        float(values["rms_px"]) < 0.2
        and float(values["uncertainty_max"]) >= float(values["uncertainty_centre"]) > 0
    )


def test_a_pinhole_report_has_no_circle_and_no_grey_cells(db: tuple[str, Path]) -> None:
    url, root = db
    out = root / "pin.html"
    assert RUNNER.invoke(app, ["--db", url, "report", "PIN-1", "-o", str(out)]).exit_code == 0
    html = out.read_text(encoding="utf-8")
    assert "Image circle" not in html and "not_imaged_cells" not in html and 'fill="#dddddd"' not in html
    assert "cells never reached shaded" in html and np.isfinite(float(shown(html)["empty_cells"]))
