"""The station loop: a folder per unit, bad lines that do not stop it, Ctrl-C at each step."""

from __future__ import annotations

import os
import shutil
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from calibctl.config import load_settings
from calibctl.errors import UsageError
from calibctl.store.repository import Store
from calibctl.workflows.camera.capture import CaptureObserver
from calibctl.workflows.station.station import (
    CANCELLED,
    ERROR,
    PASS,
    StationRequest,
    UnitResult,
    run_station,
)
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rendered(tmp_path_factory, "good")


@pytest.fixture
def settings(sqlite_url: str):
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return load_settings(db=sqlite_url, station="line-3", operator="op-ana", env={}, jobs=2)


@pytest.fixture
def shots(tmp_path: Path, good: Path) -> Path:
    """The station's watched folder: one sub-folder of pictures per unit, CAM-1 .. CAM-3."""
    for serial in ("CAM-1", "CAM-2", "CAM-3"):
        shutil.copytree(good, tmp_path / "shots" / serial, ignore=shutil.ignore_patterns("*.json"))
    return tmp_path / "shots"


def run(
    settings, shots: Path, serials, observer=CaptureObserver, board: str = "A17"
) -> tuple[list[UnitResult], bool]:
    lines: list[UnitResult] = []
    summary = run_station(
        settings, StationRequest(board, f"{shots}/{{serial}}"), serials, lines.append, observer
    )
    assert summary.units == lines
    return lines, summary.interrupted


def test_each_serial_line_calibrates_its_folder_and_blank_lines_are_skipped(settings, shots: Path) -> None:
    lines, interrupted = run(settings, shots, ["CAM-1\n", "\n", "  CAM-2  \n"])
    assert [(r.serial, r.status, r.version) for r in lines] == [("CAM-1", PASS, 1), ("CAM-2", PASS, 1)]
    assert not interrupted and all(r.rms_px is not None and r.rms_px < 0.5 and r.unit_s > 0 for r in lines)
    with Store.open(settings.db_url) as store:
        assert {s.serial for s in store.list_sessions()} == {"CAM-1", "CAM-2"}
        assert {s.station for s in store.list_sessions()} == {"line-3"}
        assert store.get_artifact("CAM-2", None).version == 1


def test_a_bad_serial_a_repeat_and_a_missing_folder_are_lines_and_the_loop_goes_on(
    settings, shots: Path
) -> None:
    lines, _ = run(settings, shots, ["CAM 1", "CAM-1", "CAM-1", "CAM-9", "CAM-2"])
    assert [(r.serial, r.status) for r in lines] == [
        ("CAM 1", ERROR),
        ("CAM-1", PASS),
        ("CAM-1", ERROR),
        ("CAM-9", ERROR),
        ("CAM-2", PASS),
    ]
    assert lines[0].message == "'CAM 1' is not a serial" and "scan the label again" in (lines[0].hint or "")
    assert lines[2].message.startswith("CAM-1 was already calibrated in this run (unit 2)")
    assert lines[3].message == f"no pictures for CAM-9: {shots}/CAM-9 does not exist"
    with Store.open(settings.db_url) as store:
        assert sorted(s.serial for s in store.list_sessions()) == ["CAM-1", "CAM-2"]  # nothing twice


def test_an_unknown_board_is_a_line_per_unit_naming_it(settings, shots: Path) -> None:
    lines, _ = run(settings, shots, ["CAM-1", "CAM-2"], board="NOPE")
    assert [r.status for r in lines] == [ERROR, ERROR]
    assert "NOPE" in lines[0].message and lines[0].hint
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == []


def test_a_template_without_the_serial_slot_is_a_usage_error(settings, shots: Path) -> None:
    with pytest.raises(UsageError, match=r"has no \{serial\}"):
        run_station(settings, StationRequest("A17", str(shots)), ["CAM-1"], lambda r: None)


def test_ctrl_c_between_units_ends_the_station_cleanly(settings, shots: Path) -> None:
    def serials() -> Iterator[str]:
        yield "CAM-1"
        raise KeyboardInterrupt  # the operator presses Ctrl-C at the serial prompt

    lines, interrupted = run(settings, shots, serials())
    assert interrupted and [(r.serial, r.status) for r in lines] == [("CAM-1", PASS)]


class CtrlCAt(CaptureObserver):
    """Sends this process a real SIGINT when image number ``at`` is detected."""

    def __init__(self, at: int | None) -> None:
        self.at = at

    def image_done(self, done: int, total: int, name: str, status: str) -> None:
        if done == (total if self.at is None else self.at):
            os.kill(os.getpid(), signal.SIGINT)


def test_ctrl_c_while_a_unit_is_detected_cancels_it_with_nothing_stored_and_the_next_unit_runs(
    settings, shots: Path
) -> None:
    observers = iter([CtrlCAt(2), CaptureObserver()])
    lines, interrupted = run(settings, shots, ["CAM-1", "CAM-2"], lambda: next(observers))
    assert [(r.serial, r.status) for r in lines] == [("CAM-1", CANCELLED), ("CAM-2", PASS)]
    assert "nothing was stored" in lines[0].message and not interrupted
    with Store.open(settings.db_url) as store:
        assert [s.serial for s in store.list_sessions()] == ["CAM-2"]


def test_ctrl_c_after_detection_is_held_until_the_unit_is_stored_then_ends_the_station(
    settings, shots: Path
) -> None:
    lines, interrupted = run(settings, shots, ["CAM-1", "CAM-2"], lambda: CtrlCAt(None))
    assert interrupted and [(r.serial, r.status) for r in lines] == [("CAM-1", PASS)]  # CAM-2 never started
    with Store.open(settings.db_url) as store:
        assert [s.serial for s in store.list_sessions()] == ["CAM-1"]
        assert store.get_artifact("CAM-1", None).version == 1
