"""calibctl diff --rig: two stored rig versions pair by pair, exit codes, --json and bad input."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.store.rig_documents import RIG, rig_calibration, rig_definition


@pytest.fixture
def db(sqlite_url: str) -> str:
    """STEREO-1 @1 and @2 at 75 mm, @3 at 76 mm (sigma 0.03 mm), @4 rejected at 75 mm."""
    with Store.open(sqlite_url, create=True) as store:
        store.add_rig(rig_definition())
        for baseline_m, status in (
            (0.075, "accepted"),
            (0.075, "accepted"),
            (0.076, "accepted"),
            (0.075, "rejected"),
        ):
            store.add_rig_calibration(
                rig_calibration(status, baseline_m),
                activate=status == "accepted",
                actor="op",
                station="st1",
                reason="test",
            )
    return sqlite_url


def _run(db: str, *args: str):
    return CliRunner().invoke(app, ["--db", db, "diff", "--rig", *args])


def test_an_unchanged_rig_is_the_same(db: str) -> None:
    result = _run(db, f"{RIG}@1", f"{RIG}@2")
    assert result.exit_code == 0, result.output
    assert f"diff rig {RIG}@1 (accepted) -> {RIG}@2 (accepted): SAME" in result.stdout
    assert "baseline 75.000 -> 75.000 mm (+0.000 +/- 0.045 mm)" in result.stdout


def test_a_1mm_longer_baseline_is_different_with_its_depth_error(db: str) -> None:
    result = _run(db, f"{RIG}@1", RIG, "--json")  # RIG: the active version, @3
    assert result.exit_code == 1, result.output
    doc = json.loads(result.stdout)
    assert doc["verdict"] == "different" and doc["b"]["ref"] == f"{RIG}@3"
    (pair,) = doc["pairs"]
    assert pair["a"] == "CAM-0001" and pair["b"] == "CAM-0002" and pair["significant"]
    assert pair["baseline_change_mm"] == pytest.approx(1.0, rel=1e-6)
    assert [d["depth_m"] for d in pair["depth"]] == [1.0, 2.0, 5.0, 10.0]
    assert pair["depth"][-1]["error_m"] == pytest.approx(-10.0 / 76.0, rel=1e-6)
    text = _run(db, f"{RIG}@1", f"{RIG}@3")
    assert "-131.6 +/- " in text.stdout and "mm at 10 m" in text.stdout and "DIFFERENT" in text.stdout


def test_a_rejected_rig_version_is_compared_and_labelled(db: str) -> None:
    result = _run(db, f"{RIG}@1", f"{RIG}@4")
    assert result.exit_code == 0, result.output
    assert f"{RIG}@4 is a REJECTED rig calibration" in result.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([f"{RIG}@2", f"{RIG}@2"], "there is nothing to compare"),
        ([f"{RIG}@1", f"{RIG}@9"], "9"),
        (["NOPE@1", f"{RIG}@1"], "NOPE"),
        ([f"{RIG}@1", f"{RIG}@2", "--scale", "2"], "--scale applies to camera diffs, not to --rig"),
        ([f"{RIG}@1", f"{RIG}@2", "--map", "x.html"], "--map applies to camera diffs"),
    ],
)
def test_bad_rig_input_exits_2(db: str, args: list[str], message: str) -> None:
    result = _run(db, *args)
    assert result.exit_code == 2, result.output
    assert message in result.stderr and "Traceback" not in result.output
