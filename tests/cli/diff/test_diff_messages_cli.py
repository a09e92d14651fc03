"""calibctl diff names the real mistake: a malformed version is not an unknown serial; two lens models are
compared where both map, not off the image."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration


@pytest.mark.parametrize("ref", ["CAM@x", "CAM@", "CAM@3.0"])
def test_a_malformed_version_is_named_not_an_unknown_serial(sqlite_url: str, ref: str) -> None:
    result = CliRunner().invoke(app, ["--db", sqlite_url, "diff", ref, "CAM@1"])
    assert result.exit_code == 2, result.output
    assert f"'{ref}' is not SERIAL or SERIAL@N: the version" in result.stderr
    assert "is not a whole number" in result.stderr and "unknown serial" not in result.stderr
    assert "calibctl history CAM" in result.stderr


def test_a_fisheye_against_a_pinhole_is_compared_over_the_region_both_map(sqlite_url: str) -> None:
    """A 150 deg fisheye's outer rays land thousands of px off a pinhole model's image: compared there, the
    difference was millions of px. Only the region both lenses map is compared, and the note says so."""
    wide = calibration(serial="WIDE", fx=200.0, cx=319.5, cy=239.5)
    fisheye = wide.model_copy(
        update={
            "dist_coeffs": [0.0, 0.0, 0.0, 0.0],
            "model": wide.model.model_copy(update={"name": "fisheye"}),
        }
    )
    pinhole = wide.model_copy(update={"version": 2, "dist_coeffs": [0.0] * 5})
    with Store.open(sqlite_url, create=True) as store:
        for art in (fisheye, pinhole):
            store.add_artifact(art, activate=True, actor="op", station="st1", reason="test")
    result = CliRunner().invoke(app, ["--db", sqlite_url, "diff", "WIDE@1", "WIDE@2", "--json"])
    doc = json.loads(result.stdout)
    assert doc["a"]["model"] == "fisheye" and doc["b"]["model"] == "k1k2"
    assert 0 < doc["samples"] < 1200 and doc["samples_outside_a_model"] == 1200 - doc["samples"]
    assert doc["raw"]["percentiles_px"]["max"] < 800  # within the image's diagonal, not millions
    assert any(n.startswith("compared over the region both lenses map") for n in doc["notes"])
