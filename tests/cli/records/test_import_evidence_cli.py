"""An imported artifact whose numbers break the identities its own evidence obeys is refused: exit 1, the
numbers named, nothing stored (calibctl/workflows/lint/evidence.py)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.calibration import CalibrationArtifact, HeldOut, ParameterCovariance, RingRms
from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.cli.real_left import calibrated_left_store

SERIAL = "CAM-E1"
runner = CliRunner()
SIGMA = {"fx": 0.84, "fy": 0.84, "cx": 0.51, "cy": 0.47, "k1": 0.002, "k2": 0.006}
COV_NAMES = ["fy", "cx", "cy", "k1", "k2"]


def consistent() -> CalibrationArtifact:
    """The factory's one-view artifact with a covariance and residual bins that agree with its figures."""
    art = calibration(serial=SERIAL, version=7)
    cov = ParameterCovariance(
        parameters=COV_NAMES,
        aspect_ratio=1.0,
        matrix=[[SIGMA[a] ** 2 if a == b else 0.0 for b in COV_NAMES] for a in COV_NAMES],
    )
    bins = [
        RingRms(label=f"quintile {i + 1}", fit_rms_px=0.284, held_out_rms_px=0.30, count=c)
        for i, c in enumerate((11, 11, 11, 11, 10))
    ]
    held = HeldOut(
        k_folds=5, rms_px=0.30, outer_ring_rms_px=0.30, fit_outer_ring_rms_px=0.284, by_radius=bins
    )
    return art.model_copy(
        update={
            "stdev": art.stdev.model_copy(update={"covariance": cov, "sigma": dict(SIGMA)}),
            "held_out": held,
        }
    ).sealed()


def _cov(art: CalibrationArtifact, i: int, j: int, value: float, both: bool = True) -> dict:
    matrix = [list(row) for row in art.stdev.covariance.matrix]
    matrix[i][j] = value
    if both:
        matrix[j][i] = value
    cov = art.stdev.covariance.model_copy(update={"matrix": matrix})
    return {"stdev": art.stdev.model_copy(update={"covariance": cov})}


def _view(art: CalibrationArtifact, **update) -> dict:
    return {"views": [art.views[0].model_copy(update=update)]}


FORGERIES: list[tuple[str, Callable[[CalibrationArtifact], dict], str]] = [
    (
        "view rms",
        lambda a: _view(a, rms_px=0.2),
        "rms_px 0.284 but its 1 view(s) of 54 corners aggregate to 0.2 px",
    ),
    (
        "fit rms",
        lambda a: {"rms_px": 0.25},
        "rms_px 0.25 but its 1 view(s) of 54 corners aggregate to 0.284 px",
    ),
    (
        "residual count",
        lambda a: {"stdev": a.stdev.model_copy(update={"residual_count": 2376})},
        "residual_count 2376 but its views hold 54 corners (108 residuals)",
    ),
    (
        "a bin",
        lambda a: {
            "held_out": a.held_out.model_copy(
                update={
                    "by_radius": [
                        a.held_out.by_radius[0].model_copy(update={"fit_rms_px": 0.1}),
                        *a.held_out.by_radius[1:],
                    ]
                }
            )
        },
        "rms_px 0.284 but its radius bins aggregate to",
    ),
    (
        "held-out rms",
        lambda a: {"held_out": a.held_out.model_copy(update={"rms_px": 0.2})},
        "held-out rms_px 0.2 but its radius bins aggregate to 0.3 px",
    ),
    (
        "outer ring",
        lambda a: {"held_out": a.held_out.model_copy(update={"outer_ring_rms_px": 0.25})},
        "held-out outer-ring RMS 0.25 but its outer radius bin says 0.3 px",
    ),
    ("asymmetric covariance", lambda a: _cov(a, 0, 1, 0.1, both=False), "its covariance is not symmetric"),
    ("indefinite covariance", lambda a: _cov(a, 0, 1, 5.0), "its covariance is not positive semi-definite"),
    (
        "sigma",
        lambda a: {"stdev": a.stdev.model_copy(update={"sigma": {**SIGMA, "cx": 0.9}})},
        "sigma_cx 0.9 but its covariance says 0.51",
    ),
    (
        "principal point",
        lambda a: {"camera_matrix": ((800.0, 0.0, 700.0), (0.0, 800.0, 240.0), (0.0, 0.0, 1.0))},
        "its principal point (700.0, 240.0) lies outside its 640x480 image",
    ),
    (
        "pose behind",
        lambda a: _view(a, tvec_m=(0.02, -0.01, -0.6)),
        "view img01.png: its board pose puts corners behind",
    ),
    (
        "pose outside",
        lambda a: _view(a, tvec_m=(2.0, -0.01, 0.6)),
        "view img01.png: 54 of its board's corners project outside the 640x480 image",
    ),
]


def _import(url: str, path: Path):
    return runner.invoke(app, ["--db", url, "import", str(path)])


def test_the_consistent_artifact_imports(sqlite_url, tmp_path):
    path = tmp_path / "ok.json"
    path.write_text(json.dumps(consistent().model_dump(mode="json")))
    result = _import(sqlite_url, path)
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize(
    ("forge", "words"), [(f, w) for _, f, w in FORGERIES], ids=[n for n, _, _ in FORGERIES]
)
def test_a_forgery_that_breaks_its_own_evidence_is_refused_and_nothing_stored(
    sqlite_url, tmp_path, forge, words
):
    art = consistent()
    path = tmp_path / "forged.json"
    path.write_text(json.dumps(art.model_copy(update=forge(art)).sealed().model_dump(mode="json")))
    result = _import(sqlite_url, path)
    assert result.exit_code == 1, result.output
    assert f"{SERIAL}@7 does not reproduce its own evidence: " in result.stderr
    assert words in result.stderr and "nothing was stored" in result.stderr
    with Store.open(sqlite_url) as store:
        assert store.serials() == []


def test_a_real_export_imports_and_one_edited_view_rms_is_refused(tmp_path):
    url = calibrated_left_store(tmp_path, "LEFT-E")
    exported = tmp_path / "left.json"
    assert runner.invoke(app, ["--db", url, "export", "LEFT-E", "-o", str(exported)]).exit_code == 0
    target = f"sqlite:///{tmp_path / 'target.db'}"
    assert _import(target, exported).exit_code == 0
    art = CalibrationArtifact.model_validate_json(exported.read_text())
    views = [art.views[0].model_copy(update={"rms_px": art.views[0].rms_px * 1.2}), *art.views[1:]]
    forged = tmp_path / "forged.json"
    forged.write_text(
        json.dumps(
            art.model_copy(update={"views": views, "signature": None}).sealed().model_dump(mode="json")
        )
    )
    other = f"sqlite:///{tmp_path / 'other.db'}"
    result = _import(other, forged)
    assert result.exit_code == 1 and "LEFT-E@1 does not reproduce its own evidence: rms_px" in result.stderr
    with Store.open(other) as store:
        assert store.serials() == []
