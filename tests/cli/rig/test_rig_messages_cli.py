"""rig solve-folders names the real mistake: a pattern that is part of the board seen, a square size no
printed board has (the rendered 75 mm rig of tests/workflows/rig_folders_data.py, shared per process)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from tests.workflows.rig_folders_data import rendered_rig, rig_sources


@pytest.fixture(scope="module")
def rig2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rendered_rig(tmp_path_factory)


def solve_folders(rig2: Path, cols: str, square_mm: str, *extra: str):
    args = ["rig", "solve-folders", *rig_sources(rig2)]
    args += ["--cols", cols, "--rows", "6", "--square-mm", square_mm, "--min-shared-views", "5", *extra]
    return CliRunner().invoke(app, args, terminal_width=200)


def test_a_pattern_one_column_short_names_the_board_seen_not_the_views(rig2: Path) -> None:
    res = solve_folders(rig2, "8", "25")
    assert res.exit_code == 2, res.output
    # rendered views show no 8x6 part of the board (opencv-left-right's photos do: "a larger board")
    assert "no 8x6 chessboard (given as --cols 8 --rows 6) was found" in res.stderr
    assert "photos of camera CAM0" in res.stderr and "a 9x6 chessboard is visible in" in res.stderr
    assert "check --cols/--rows and give the board seen, 9x6 inner corners" in res.stderr
    assert "needs 3 views" not in res.output


def test_a_square_size_no_board_has_is_a_warning_naming_the_baseline_it_makes(rig2: Path) -> None:
    res = solve_folders(rig2, "9", "2.5", "--json")
    doc = json.loads(res.stdout)
    found = [f for f in doc["lint"] if f["rule"] == "square-size"]
    assert len(found) == 1 and found[0]["severity"] == "warning", doc["lint"]
    assert "--square-mm 2.5 is outside the 5-300 mm" in found[0]["message"]
    assert "it makes the baseline 7." in found[0]["message"] and "millimetres" in found[0]["fix"]


def test_the_right_square_size_raises_no_warning(rig2: Path) -> None:
    doc = json.loads(solve_folders(rig2, "9", "25", "--json").stdout)
    assert not [f for f in doc["lint"] if f["rule"] == "square-size"]


def test_the_unit_square_measures_in_squares_without_a_warning(rig2: Path) -> None:
    doc = json.loads(solve_folders(rig2, "9", "1", "--json").stdout)
    assert not [f for f in doc["lint"] if f["rule"] == "square-size"]
