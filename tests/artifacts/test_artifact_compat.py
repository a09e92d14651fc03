"""rejected_corners and camera_consistency joined the calibration artifact after artifacts were stored:
old ones still read and verify, new ones are covered by the hash."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import ValidationError

from calibctl.artifacts.calibration import (
    CalibrationArtifact,
    CameraConsistency,
    ParameterCovariance,
    RejectedCorner,
    ViewLevelSigma,
)
from calibctl.artifacts.common import canonical_json_bytes, parse_document, sha256_hex
from tests.artifacts.factories import calibration

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "camera_front.json"


def _as_written_before_the_field(art: CalibrationArtifact) -> dict:
    """The document an older calibctl wrote: neither key (nor the later content_hash_algorithm and
    signature), sealed the way it sealed (the legacy canonical JSON)."""
    data = art.model_dump(mode="json")
    assert "rejected_corners" not in data and "camera_consistency" not in data  # left out while empty
    data.pop("content_hash_algorithm")
    data.pop("signature")
    body = {k: v for k, v in data.items() if k != "content_sha256"}
    data["content_sha256"] = sha256_hex(canonical_json_bytes(body))
    return data


def test_an_artifact_written_before_the_field_reads_and_verifies() -> None:
    old = _as_written_before_the_field(calibration())
    art = parse_document(CalibrationArtifact, old, "old.json")
    assert art.rejected_corners == [] and art.camera_consistency is None
    assert art.computed_sha256() == old["content_sha256"]


def test_the_committed_fixture_still_verifies() -> None:
    data = json.loads(FIXTURE.read_text(encoding="utf-8"))
    assert "rejected_corners" not in data
    art = parse_document(CalibrationArtifact, data, FIXTURE.name)
    assert art.computed_sha256() == data["content_sha256"]


def test_rejected_corners_are_covered_by_the_hash() -> None:
    corner = RejectedCorner(view="img01.png", corner_id=45, residual_px=15.3, dx_px=9.0, dy_px=-12.4)
    art = calibration().model_copy(update={"rejected_corners": [corner]}).sealed()
    assert art.computed_sha256() == art.content_sha256
    tampered = art.model_copy(update={"rejected_corners": [corner.model_copy(update={"residual_px": 1.0})]})
    assert tampered.computed_sha256() != art.content_sha256
    again = parse_document(CalibrationArtifact, json.loads(art.model_dump_json()), "new.json")
    assert again.rejected_corners == [corner] and again.computed_sha256() == art.content_sha256


def test_the_two_camera_check_is_covered_by_the_hash() -> None:
    check = CameraConsistency(
        group_a=["left01.jpg"],
        group_b=["right01.jpg"],
        holdout_rms_px=(0.19, 0.19),
        cross_rms_px=(0.32, 0.33),
        fx_px=(533.0, 537.0),
        cx_px=(342.0, 326.0),
        cy_px=(234.0, 249.0),
        ratio=1.68,
        threshold=1.4,
        two_cameras_suspected=True,
    )
    art = calibration().model_copy(update={"camera_consistency": check}).sealed()
    assert art.computed_sha256() == art.content_sha256 != calibration().content_sha256
    flipped = art.model_copy(
        update={"camera_consistency": check.model_copy(update={"two_cameras_suspected": False})}
    )
    assert flipped.computed_sha256() != art.content_sha256


def test_an_artifact_written_before_the_covariance_reads_and_verifies() -> None:
    old = _as_written_before_the_field(calibration())
    assert "covariance" not in old["stdev"]  # left out while None
    art = parse_document(CalibrationArtifact, old, "old.json")
    assert art.stdev.covariance is None and art.computed_sha256() == old["content_sha256"]


def test_the_covariance_is_covered_by_the_hash_and_checked_for_shape() -> None:
    cov = ParameterCovariance(parameters=["fy", "cx"], matrix=[[0.04, 0.01], [0.01, 0.09]], aspect_ratio=1.0)
    base = calibration()
    art = base.model_copy(update={"stdev": base.stdev.model_copy(update={"covariance": cov})}).sealed()
    assert art.computed_sha256() == art.content_sha256 != base.content_sha256
    edited = cov.model_copy(update={"matrix": [[0.04, 0.01], [0.01, 0.08]]})
    tampered = art.model_copy(update={"stdev": art.stdev.model_copy(update={"covariance": edited})})
    assert tampered.computed_sha256() != art.content_sha256
    with pytest.raises(ValidationError, match="2x2"):
        ParameterCovariance(parameters=["fy", "cx"], matrix=[[0.04, 0.01]])
    with pytest.raises(ValidationError, match="distinct names"):
        ParameterCovariance(parameters=["fy", "zoom"], matrix=[[0.04, 0.01], [0.01, 0.09]])


def test_an_artifact_written_before_the_view_level_check_reads_and_verifies() -> None:
    old = _as_written_before_the_field(calibration())
    assert "view_level" not in old["stdev"]  # left out while None
    art = parse_document(CalibrationArtifact, old, "old.json")
    assert art.stdev.view_level is None and art.computed_sha256() == old["content_sha256"]


def test_the_view_level_check_round_trips_and_is_covered_by_the_hash() -> None:
    check = ViewLevelSigma(sigma_factor=2.41, views=13, used="view-level", rule="sigma x sqrt(phi) when ...")
    base = calibration()
    art = base.model_copy(update={"stdev": base.stdev.model_copy(update={"view_level": check})}).sealed()
    assert art.computed_sha256() == art.content_sha256 != base.content_sha256
    again = parse_document(CalibrationArtifact, json.loads(art.model_dump_json()), "new.json")
    assert again.stdev.view_level == check and again.computed_sha256() == art.content_sha256
    flipped = art.model_copy(
        update={
            "stdev": art.stdev.model_copy(
                update={"view_level": check.model_copy(update={"used": "jacobian"})}
            )
        }
    )
    assert flipped.computed_sha256() != art.content_sha256
    with pytest.raises(ValidationError, match="used"):
        ViewLevelSigma(sigma_factor=1.0, views=13, used="bootstrap", rule="r")  # type: ignore[arg-type]
