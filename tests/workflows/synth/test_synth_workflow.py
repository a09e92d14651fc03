"""The synth workflow's own contracts: truth files, board specs, and what it refuses."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.errors import InputError, UsageError
from calibctl.workflows.synth.synth import load_truth, parse_size, run_synth


def test_truth_round_trips_and_foreign_files_are_refused(tmp_path: Path) -> None:
    result = run_synth(tmp_path / "s", "flat", seed=1, views=2, image_size=(320, 240))
    truth = load_truth(result.truth_path)
    assert truth["generator"] == {**truth["generator"], "scenario": "flat", "seed": 1}
    assert [v["file"] for v in truth["views"]] == ["view-000.png", "view-001.png"]
    assert all(v["tilt_deg"] < 5.0 for v in truth["views"])
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"schema": "something/else"}))
    with pytest.raises(InputError, match="is not a calibctl synth truth file"):
        load_truth(other)
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    with pytest.raises(InputError, match="malformed JSON"):
        load_truth(broken)


def test_unknown_scenario_and_pattern_are_usage_errors(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="unknown scenario 'tilted'") as info:
        run_synth(tmp_path / "a", "tilted")
    assert info.value.hint == "choose one of good, flat, centre, one-direction, video"
    with pytest.raises(UsageError, match="unknown pattern 'dots'"):
        run_synth(tmp_path / "a", "good", pattern="dots")
    assert not (tmp_path / "a").exists()


@pytest.mark.parametrize(("text", "size"), [("640x480", (640, 480)), ("1280X720", (1280, 720))])
def test_parse_size(text: str, size: tuple[int, int]) -> None:
    assert parse_size(text) == size


def test_board_specs_refuse_impossible_boards() -> None:
    with pytest.raises(ValueError, match="unknown board kind 'dots'"):
        BoardSpec("dots", 9, 6, 0.025)
    with pytest.raises(ValueError, match="at least 2x2 inner corners, got 1x6"):
        BoardSpec.chessboard(1, 6, 0.025)
    with pytest.raises(ValueError, match="square size must be positive"):
        BoardSpec.chessboard(9, 6, 0.0)
    with pytest.raises(ValueError, match="0 < marker_size_m < square_size_m"):
        BoardSpec.charuco(10, 7, 0.025, 0.03)
    with pytest.raises(ValueError, match="unknown ArUco dictionary 'DICT_9X9_1'"):
        BoardSpec.charuco(10, 7, 0.025, 0.018, "DICT_9X9_1")
