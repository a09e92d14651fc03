"""calibctl diff from the command line: verdicts and exit codes, --json, --map, and every bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.artifacts.calibration import CalibrationArtifact, ParameterCovariance, Uncertainty
from calibctl.cli.main import app
from calibctl.core.intrinsics.solve import IntrinsicsSolution
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.core.compare.sessions import solve, true_K


def _artifact(
    serial: str, fit: IntrinsicsSolution, status: str = "accepted", scale: float = 1.0, model: str = "k1k2"
) -> CalibrationArtifact:
    """A stored calibration carrying ``fit``'s lens and covariance (``scale``: read out that much smaller)."""
    cov = fit.covariance
    assert cov is not None and cov.covariance is not None
    K = np.array(fit.camera_matrix)
    K[:2, :] *= scale
    K[0, 2], K[1, 2] = (
        scale * (fit.camera_matrix[0, 2] + 0.5) - 0.5,
        scale * (fit.camera_matrix[1, 2] + 0.5) - 0.5,
    )
    t = np.array([scale if n in ("fx", "fy", "cx", "cy") else 1.0 for n in cov.names])
    base = calibration(
        serial=serial,
        status=status,
        image_size=(round(fit.image_size[0] * scale), round(fit.image_size[1] * scale)),
    )
    stdev = Uncertainty(
        sigma=dict(fit.sigma),
        residual_count=fit.n_residuals,
        parameter_count=fit.n_parameters,
        covariance=ParameterCovariance(
            parameters=list(cov.names),
            matrix=(cov.covariance * np.outer(t, t)).tolist(),
            aspect_ratio=fit.aspect_ratio,
        ),
    )
    return base.model_copy(
        update={
            "camera_matrix": tuple(tuple(float(v) for v in row) for row in K),
            "dist_coeffs": [float(v) for v in fit.dist_coeffs],
            "stdev": stdev,
            "model": base.model.model_copy(update={"name": model}),
        }
    )


@pytest.fixture(scope="module")
def fits() -> dict[str, IntrinsicsSolution]:
    return {
        "a": solve(true_K(), 11),
        "b": solve(true_K(), 12),
        "focal": solve(true_K(focal_scale=1.003), 13),
        "k3": solve(true_K(), 12, model="k1k2k3"),
    }


@pytest.fixture
def db(sqlite_url: str, fits: dict[str, IntrinsicsSolution]) -> str:
    """CAM@1 and CAM@2: one camera twice; CAM@3 its focal 0.3 % longer (active); CAM@4 rejected;
    HALF@1 CAM@1 read out at half resolution; OLD@1 without a covariance; K3@1 a k1k2k3 solve."""
    with Store.open(sqlite_url, create=True) as store:

        def add(art: CalibrationArtifact, activate: bool = True) -> None:
            store.add_artifact(art, activate=activate, actor="op", station="st1", reason="test")

        add(_artifact("CAM", fits["a"]))
        add(_artifact("CAM", fits["b"]))
        add(_artifact("CAM", fits["focal"]))
        add(_artifact("CAM", fits["b"], status="rejected"), activate=False)
        add(_artifact("HALF", fits["a"], scale=0.5))
        add(calibration(serial="OLD"))
        add(_artifact("K3", fits["k3"], model="k1k2k3"))
    return sqlite_url


def _run(db: str, *args: str):
    return CliRunner().invoke(app, ["--db", db, "diff", *args])


def test_one_camera_recalibrated_is_the_same_and_exits_0(db: str) -> None:
    result = _run(db, "CAM@1", "CAM@2")
    assert result.exit_code == 0, result.output
    assert "diff CAM@1 (k1k2, accepted) -> CAM@2 (k1k2, accepted): SAME" in result.stdout
    assert "within noise: chi2" in result.stdout and "expected sigma" in result.stdout


def test_a_changed_focal_length_is_different_and_exits_1(db: str) -> None:
    result = _run(db, "CAM@1", "CAM")  # CAM: the active version, @3
    assert result.exit_code == 1, result.output
    assert "-> CAM@3 (k1k2, accepted): DIFFERENT" in result.stdout and "as stored: chi2" in result.stdout


def test_json_carries_percentiles_the_test_and_the_fitted_rotation(db: str) -> None:
    result = _run(db, "CAM@1", "CAM@3", "--json")
    assert result.exit_code == 1, result.output
    doc = json.loads(result.stdout)
    assert doc["verdict"] == "different" and doc["a"]["ref"] == "CAM@1" and doc["b"]["ref"] == "CAM@3"
    assert set(doc["raw"]["percentiles_px"]) == {"p50", "p90", "p99", "max"}
    assert doc["raw"]["chi2"]["dof"] == 5 and doc["raw"]["chi2"]["p_value"] < 1e-6
    assert doc["fit"]["rotation_deg"] >= 0 and len(doc["fit"]["rvec_rad"]) == 3 and doc["range_m"] is None
    assert doc["samples"] == 1200 and doc["alpha"] == 0.01


def test_a_map_page_is_written_and_never_overwritten_without_force(db: str, tmp_path: Path) -> None:
    page = tmp_path / "diff.html"
    result = _run(db, "CAM@1", "CAM@2", "--map", str(page), "--grid", "16x12")
    assert result.exit_code == 0, result.output
    text = page.read_text(encoding="utf-8")
    assert text.count("<svg") >= 3 and "CAM@1 vs CAM@2: same within noise" in text
    again = _run(db, "CAM@1", "CAM@2", "--map", str(page))
    assert again.exit_code == 2 and "already exists" in again.stderr and "--force" in again.stderr
    assert _run(db, "CAM@1", "CAM@2", "--map", str(page), "--force").exit_code == 0


def test_a_finite_range_fits_a_translation_too(db: str) -> None:
    result = _run(db, "CAM@1", "CAM@2", "--range-m", "2.0", "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["range_m"] == 2.0


def test_a_rejected_version_is_compared_and_labelled(db: str) -> None:
    result = _run(db, "CAM@1", "CAM@4")
    assert result.exit_code == 0, result.output
    assert "CAM@4 (k1k2, rejected)" in result.stdout and "CAM@4 is a REJECTED calibration" in result.stdout


def test_different_image_sizes_need_a_stated_scale(db: str) -> None:
    result = _run(db, "CAM@1", "HALF@1")
    assert result.exit_code == 2
    assert "CAM@1 is 640x480 and HALF@1 is 320x240" in result.stderr and "--scale" in result.stderr
    assert "S = 2" in result.stderr
    wrong = _run(db, "CAM@1", "HALF@1", "--scale", "3")
    assert wrong.exit_code == 2 and "not CAM@1's 640x480" in wrong.stderr
    scaled = _run(db, "CAM@1", "HALF@1", "--scale", "2", "--json")
    assert scaled.exit_code == 0, scaled.output
    doc = json.loads(scaled.stdout)
    assert doc["raw"]["percentiles_px"]["max"] < 1e-6 and "scaled by 2" in " ".join(doc["notes"])


def test_different_lens_models_are_compared_by_projection_with_a_note(db: str) -> None:
    result = _run(db, "CAM@2", "K3@1")
    assert result.exit_code == 0, result.output
    assert "different lens models (k1k2 and k1k2k3): compared by projection" in result.stdout


def test_a_calibration_without_covariance_gives_numbers_and_exits_2(db: str) -> None:
    result = _run(db, "CAM@1", "OLD@1")
    assert result.exit_code == 2
    assert "|d| p50" in result.stdout and "UNKNOWN" in result.stdout
    assert "OLD@1 stores no covariance" in result.stderr and "re-solve" in result.stderr


@pytest.mark.parametrize(
    ("a", "b", "message"),
    [
        ("CAM@2", "CAM@2", "are both CAM@2: there is nothing to compare"),
        ("CAM", "CAM@3", "are both CAM@3: there is nothing to compare"),
        ("NOPE", "CAM@1", "NOPE"),
        ("CAM@1", "CAM@9", "CAM has no version 9"),
        ("CAM@99999999999", "CAM@1", "out of range"),
    ],
)
def test_bad_refs_exit_2_naming_them(db: str, a: str, b: str, message: str) -> None:
    result = _run(db, a, b)
    assert result.exit_code == 2, result.output
    assert message in result.stderr and "Traceback" not in result.output


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--grid", "40by30"], "is not COLSxROWS"),
        (["--grid", "2x2"], "out of range"),
        (["--range-m", "-1"], "--range-m must be positive"),
        (["--scale", "0"], "--scale must be a positive number"),
    ],
)
def test_bad_options_exit_2(db: str, option: list[str], message: str) -> None:
    result = _run(db, "CAM@1", "CAM@2", *option)
    assert result.exit_code == 2 and message in result.stderr
