"""`calibctl report SERIAL` draws the diff against the previous accepted version and, when robots reported on
the serial, its field trends; what cannot be compared is said, not drawn."""

from __future__ import annotations

import json
import re
from datetime import timedelta
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.common import utc_now
from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


@pytest.fixture
def db(sqlite_url: str) -> str:
    """CAM-1: @1 and @2 one lens, @3 rejected, @4 fx + 8 px; CAM-2: @1 640x480, @2 1280x960."""
    with Store.open(sqlite_url, create=True) as store:
        for status, fx in (
            ("accepted", 800.0),
            ("accepted", 800.0),
            ("rejected", 800.0),
            ("accepted", 808.0),
        ):
            store.add_artifact(
                calibration(serial="CAM-1", status=status, fx=fx), activate=status == "accepted", **WHO
            )
        store.add_artifact(calibration(serial="CAM-2"), activate=True, **WHO)
        store.add_artifact(
            calibration(serial="CAM-2", image_size=(1280, 960), cx=640.0, cy=480.0), activate=True, **WHO
        )
    return sqlite_url


def _page(db: str, tmp_path: Path, ref: str) -> str:
    out = tmp_path / f"{ref}.html"
    result = CliRunner().invoke(app, ["--db", db, "report", ref, "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out.read_text()


def _key(html: str, key: str) -> str:
    match = re.search(rf'data-key="{key}">([^<]*)<', html)
    assert match is not None, key
    return match.group(1)


def test_the_diff_against_the_previous_accepted_version(db: str, tmp_path: Path) -> None:
    same = _page(db, tmp_path, "CAM-1@2")
    assert "<code>calibctl diff CAM-1@1 CAM-1@2</code>" in same
    assert float(_key(same, "diff_raw_max")) < 1e-6
    changed = _page(db, tmp_path, "CAM-1@4")  # @3 is rejected: the previous accepted version is @2
    assert "<code>calibctl diff CAM-1@2 CAM-1@4</code>" in changed
    # fx 800 -> 808 px: a pixel at the corner (320, 240) px off-centre moves by about 1 % of that, 4 px
    assert 3.0 < float(_key(changed, "diff_raw_max")) < 5.0
    assert float(_key(changed, "diff_raw_p50")) < float(_key(changed, "diff_raw_max"))
    first = _page(db, tmp_path, "CAM-1@1")
    assert "no accepted version of CAM-1 before @1 to compare with" in first
    assert "Field health" not in first  # no robot reported on CAM-1


def test_two_image_sizes_are_named_not_compared(db: str, tmp_path: Path) -> None:
    html = _page(db, tmp_path, "CAM-2@2")
    assert "CAM-2@1 and CAM-2@2 were not compared:" in html and "diff_verdict" not in html


def test_the_trends_section_when_robots_reported(db: str, tmp_path: Path) -> None:
    runner = CliRunner()
    assert runner.invoke(app, ["--db", db, "fleet", "add", "amr-1", "--serial", "CAM-1"]).exit_code == 0
    now = utc_now()
    lines = [
        {
            "source_id": f"c/{d}",
            "serial": "CAM-1",
            "robot": "amr-1",
            "kind": "check",
            "verdict": "pass",
            "time": (now - timedelta(days=d)).isoformat(),
            "rms_px": 0.2 + 0.01 * d,
            "temperature_c": 10.0 + 3 * d,
        }
        for d in range(6)
    ]
    path = tmp_path / "r.jsonl"
    path.write_text("\n".join(json.dumps(line) for line in lines))
    assert runner.invoke(app, ["--db", db, "fleet", "ingest", str(path)]).exit_code == 0
    html = _page(db, tmp_path, "CAM-1@2")
    assert _key(html, "trends_counts") == "6 check"
    assert "RMS vs temperature: +0.0033 +- 0.0000 px/degC (n 6)" in html
    assert "check: 6 pass" in html
