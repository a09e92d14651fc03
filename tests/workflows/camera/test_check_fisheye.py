"""`calibctl check` of a fisheye calibration goes through the stored fisheye model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from calibctl.workflows.camera.check import stored_covariance
from calibctl.workflows.synth.synth import run_synth
from tests.artifacts.factories import measured_board

RUNNER = CliRunner()


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


@pytest.fixture(scope="module")
def fisheye_db(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    root = tmp_path_factory.mktemp("check-fisheye")
    url = f"sqlite:///{root / 'calibctl.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    run_synth(root / "cal", seed=1, views=12, fisheye_fov_deg=150.0)
    run_synth(root / "fresh", seed=2, views=10, fisheye_fov_deg=150.0)
    done = invoke(
        url,
        "calibrate",
        "--serial",
        "FE-0001",
        "--board",
        "A17",
        "--source",
        str(root / "cal"),
        "--model",
        "fisheye",
    )
    assert done.exit_code == 0, done.output
    return url, root / "fresh"


def test_fresh_views_of_the_same_fisheye_pass_through_the_fisheye_model(fisheye_db) -> None:
    url, fresh = fisheye_db
    done = invoke(url, "check", "FE-0001", "--source", str(fresh), "--json")
    assert done.exit_code == 0, done.output
    event = json.loads(done.stdout)
    assert event["passed"] and len(event["views"]) == 10
    overall = event["regions"][0]
    assert overall["region"] == "overall" and 0.5 < overall["ratio"] < overall["limit"]
    assert max(event["view_rms_px"]) < 0.1  # a pinhole refit leaves pixels here, not hundredths
    assert [s["parameter"] for s in event["shifts"]] == ["focal", "cx", "cy"]


def test_the_stored_covariance_of_focal_and_principal_point_matches_the_stored_sigmas(fisheye_db) -> None:
    url, _ = fisheye_db
    with Store.open(url) as store:
        art = store.get_artifact("FE-0001", None)
    cov = stored_covariance(art)
    assert cov is not None and cov.shape == (3, 3) and np.allclose(cov, cov.T)
    sigma = art.stdev.sigma
    # focal scale = mean of dfx/fx and dfy/fy: its variance lies between 0 and the larger relative variance
    rel = max(sigma["fx"] / art.camera_matrix[0][0], sigma["fy"] / art.camera_matrix[1][1])
    assert 0 < np.sqrt(cov[0, 0]) <= rel * (1 + 1e-9)
    assert np.sqrt(np.diag(cov))[1:] == pytest.approx([sigma["cx"], sigma["cy"]], rel=1e-9)
