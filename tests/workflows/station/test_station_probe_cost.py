"""No slow path hidden in a check: a station unit with failed views costs a small multiple of a clean one.

Counted, not timed: every chessboard detector call (classic and SB) the unit makes and the pixels it
searches, those of the pattern check's probes (``pattern_check``: the larger-board and nothing-found probes)
apart.
The pictures are the rendered 640x480 views scaled to 1280x960, where the probes used to search full-size
copies (4.66 s of one 20-view station unit: issue "a station unit at the speed of a plain loop").
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from calibctl.config import load_settings
from calibctl.store.repository import Store
from calibctl.workflows.camera import pattern_check
from calibctl.workflows.station.station import ERROR, FAIL, PASS, StationRequest, UnitResult, run_station
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered

SIZE = (1280, 960)
DETECTORS = ("findChessboardCorners", "findChessboardCornersSB", "findChessboardCornersSBWithMeta")
# A failed view is searched by every level of the detector (classic at half and full size, then SB) where a
# clean one is found at the first: 3 calls against 1; the probes add at most 3 SB calls and 9 classic
# detections (2 calls each), on reduced copies.
MAX_CALLS_VS_CLEAN = 6
MAX_PROBE_PIXELS_VS_CLEAN = (
    2.0  # the probes' searched pixels against all of a clean unit's (measured 0.7 and 1.5)
)


@pytest.fixture(scope="module")
def shots(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """CLEAN: the 12 rendered views at 1280x960; ONE-BOARD: the board in one of them, the others blurred
    past finding it (readable, no board); NO-BOARD: every one blurred; BLACK: every one black (a camera
    delivering black frames, a lens cap)."""
    good = sorted(rendered(tmp_path_factory, "good").glob("*.png"))
    root = tmp_path_factory.mktemp("probe-cost") / "shots"
    for serial in ("CLEAN", "ONE-BOARD", "NO-BOARD"):
        (root / serial).mkdir(parents=True)
        for i, path in enumerate(good):
            big = cv2.resize(
                cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), SIZE, interpolation=cv2.INTER_LINEAR
            )
            if serial == "NO-BOARD" or (serial == "ONE-BOARD" and i > 0):
                big = cv2.GaussianBlur(big, (0, 0), 25)
            cv2.imwrite(str(root / serial / path.name), big)
    (root / "BLACK").mkdir()
    for path in good:
        cv2.imwrite(str(root / "BLACK" / path.name), np.zeros(SIZE[::-1], np.uint8))
    return root


@pytest.fixture
def counted(monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, Counter[str]]]:
    """Detector calls and searched pixels per phase: "detect" (the pictures) and "probe" (the checks)."""
    counts: dict[str, Counter[str]] = {"detect": Counter(), "probe": Counter()}
    phase = ["detect"]
    for name in DETECTORS:
        real = getattr(cv2, name)

        def call(image: Any, *args: Any, _real: Any = real, _name: str = name, **kwargs: Any) -> Any:
            counts[phase[0]][_name] += 1
            counts[phase[0]]["pixels"] += int(image.shape[0] * image.shape[1])
            counts[phase[0]]["max_pixels"] = max(
                counts[phase[0]]["max_pixels"], image.shape[0] * image.shape[1]
            )
            return _real(image, *args, **kwargs)

        monkeypatch.setattr(cv2, name, call)
    for name in ("larger_board_error", "nothing_found_error"):
        real_check = getattr(pattern_check, name)

        def check(*args: Any, _real: Any = real_check, **kwargs: Any) -> Any:
            phase[0] = "probe"
            try:
                return _real(*args, **kwargs)
            finally:
                phase[0] = "detect"

        monkeypatch.setattr(pattern_check, name, check)
    yield counts


def _unit(shots: Path, tmp_path: Path, serial: str) -> UnitResult:
    url = f"sqlite:///{tmp_path / f'{serial}.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    settings = load_settings(db=url, station="line-3", operator="op-ana", env={}, jobs=1)  # detected here
    lines: list[UnitResult] = []
    run_station(
        settings,
        StationRequest("A17", f"{shots}/{{serial}}", spool=tmp_path / f"{serial}.sqlite"),
        [serial],
        lines.append,
    )
    return lines[0]


def _calls(counts: Counter[str]) -> int:
    return sum(counts[name] for name in DETECTORS)


def test_a_unit_with_failed_views_costs_a_small_multiple_of_a_clean_one(
    shots: Path, tmp_path: Path, counted: dict[str, Counter[str]]
) -> None:
    clean = _unit(shots, tmp_path, "CLEAN")
    assert clean.status == PASS, clean.message
    clean_calls = _calls(counted["detect"]) + _calls(counted["probe"])
    clean_pixels = counted["detect"]["pixels"]
    assert _calls(counted["probe"]) == 0  # every probed view shows the board's margin: no probe
    for serial, status in (("ONE-BOARD", FAIL), ("NO-BOARD", ERROR)):
        for phase in counted.values():
            phase.clear()
        line = _unit(shots, tmp_path, serial)
        assert line.status == status, line.message  # one view: rejected by the gates; none: the unit's error
        probe = counted["probe"]
        assert (
            _calls(probe) > 0
            and _calls(counted["detect"]) + _calls(probe) <= MAX_CALLS_VS_CLEAN * clean_calls
        )
        # SB, the slow detector, at most once per probed picture; every probe on a reduced copy
        assert (
            probe["findChessboardCornersSBWithMeta"] + probe["findChessboardCornersSB"]
            <= pattern_check.PROBE_IMAGES
        )
        assert 0 < probe["max_pixels"] <= pattern_check.PROBE_MAX_PIXELS < SIZE[0] * SIZE[1]
        assert probe["pixels"] <= MAX_PROBE_PIXELS_VS_CLEAN * clean_pixels, (
            serial,
            probe,
            counted["detect"],
            clean_pixels,
        )


def test_a_unit_of_black_pictures_searches_none_of_them(
    shots: Path, tmp_path: Path, counted: dict[str, Counter[str]]
) -> None:
    """A picture of one grey level is not searched (core.capture.detect.search_levels): the unit's detector
    calls are its probes' alone, fewer than a clean unit's, and it ends in its error line."""
    clean = _unit(shots, tmp_path, "CLEAN")
    assert clean.status == PASS, clean.message
    clean_calls = _calls(counted["detect"])
    for phase in counted.values():
        phase.clear()
    line = _unit(shots, tmp_path, "BLACK")
    assert line.status == ERROR
    assert "no 9x6 chessboard (board A17@1) was found in any of the 12 readable" in line.message
    assert _calls(counted["detect"]) == 0
    assert _calls(counted["probe"]) <= clean_calls
