"""The station's watch mode: pictures detected as they land, the unit captured when complete.

A feeder thread renames pictures into the unit's folder one by one; a slow writer writes one in place,
in lockstep with the station's polls (deterministic: the station's clock and sleep are the test's).
"""

from __future__ import annotations

import functools
import os
import shutil
import signal
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from calibctl.config import load_settings
from calibctl.core.capture import image_outcomes
from calibctl.errors import UsageError
from calibctl.store.repository import Store
from calibctl.workflows.camera.capture import CaptureRequest, capture
from calibctl.workflows.camera.distance_gauge import gauge_model
from calibctl.workflows.station import station as station_module
from calibctl.workflows.station.station import (
    CANCELLED,
    ERROR,
    PASS,
    QUEUED,
    StationRequest,
    UnitResult,
    run_station,
)
from calibctl.workflows.station.watch import WatchRule, watch_unit
from tests.workflows.station.spool_setup import away, central_folder, central_store, unit_folders
from tests.workflows.synth_folders import rendered


@pytest.fixture
def pictures(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """12 rendered views (rendered once per process; never written to)."""
    return sorted(rendered(tmp_path_factory, "good").glob("*.png"))


@pytest.fixture(params=[1, 2], ids=["jobs1", "jobs2"])
def settings(request: pytest.FixtureRequest, sqlite_url: str):
    return load_settings(db=central_store(sqlite_url), station="line-3", env={}, jobs=request.param)


def station(settings, shots: Path, serials: list[str], rule: WatchRule) -> list[UnitResult]:
    lines: list[UnitResult] = []
    summary = run_station(
        settings, StationRequest("A17", f"{shots}/{{serial}}", watch=rule), serials, lines.append
    )
    assert summary.units == lines and not summary.interrupted
    return lines


class Feeder(threading.Thread):
    """A camera app: each picture written under a temporary name, then renamed into the unit's folder."""

    def __init__(
        self,
        folder: Path,
        files: list[Path],
        pause: threading.Event | None = None,
        then: Callable[[], None] | None = None,
    ) -> None:
        super().__init__(daemon=True)
        self.folder, self.files, self.then = folder, files, then
        self.pause = pause or threading.Event()

    def run(self) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)  # the app makes the unit's folder after the serial
        for source in self.files:
            self.pause.wait(0.03)  # the operator moves the board (never set: a plain delay)
            part = self.folder / (source.name + ".part")  # not an image by its suffix: never listed
            shutil.copyfile(source, part)
            os.replace(part, self.folder / source.name)
        if self.then is not None:
            self.then()


def feed_from_first_poll(monkeypatch: pytest.MonkeyPatch, feeder: Feeder) -> None:
    """The feeder starts when the station first waits for the unit's pictures (the serial is read)."""

    def sleep(seconds: float) -> None:
        if feeder.ident is None:
            feeder.start()
        threading.Event().wait(seconds)

    monkeypatch.setattr(station_module, "watch_unit", functools.partial(watch_unit, sleep=sleep))


def batch_session(settings, folder: Path):
    """The capture `calibctl calibrate` would make of the finished folder (not stored)."""
    request = CaptureRequest(
        "CAM-B", "A17", str(folder), jobs=settings.jobs, gauge_model=gauge_model("k1k2"), lens_model="k1k2"
    )
    return capture(settings, request, store_session=False).session


def same_capture(a, b) -> None:
    assert [o.model_dump() for o in a.outcomes] == [o.model_dump() for o in b.outcomes]
    assert [(v.name, v.image_sha256, v.corner_ids, v.corners_px, v.tilt_deg) for v in a.views] == [
        (v.name, v.image_sha256, v.corner_ids, v.corners_px, v.tilt_deg) for v in b.views
    ]
    assert [(g.gate, g.passed, g.value) for g in a.gates] == [(g.gate, g.passed, g.value) for g in b.gates]
    assert (a.status, a.image_size) == (b.status, b.image_size)


def test_pictures_renamed_in_one_by_one_give_the_batch_capture_of_the_same_folder(
    settings, tmp_path: Path, pictures: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    shots = tmp_path / "shots"
    junk = tmp_path / "junk"
    junk.mkdir()
    (junk / "broken.png").write_bytes(
        pictures[0].read_bytes()[:400]
    )  # a truncated picture: unreadable, as today
    (junk / "notes.txt").write_text("not a picture")  # not an image by its suffix: ignored, as today
    feeder = Feeder(shots / "CAM-1", [*pictures, junk / "broken.png", junk / "notes.txt"])
    feed_from_first_poll(monkeypatch, feeder)
    lines = station(settings, shots, ["CAM-1"], WatchRule(views=len(pictures) + 1, settle_s=0.0))
    feeder.join()
    assert [(r.serial, r.status, r.views) for r in lines] == [("CAM-1", PASS, len(pictures))]
    assert lines[0].after_last_image_s is not None and 0 <= lines[0].after_last_image_s <= lines[0].unit_s
    with Store.open(settings.db_url) as store:
        watched = store.get_session(lines[0].session_id)  # type: ignore[arg-type]
    same_capture(watched, batch_session(settings, shots / "CAM-1"))
    assert [o.status for o in watched.outcomes if o.name == "broken.png"] == ["unreadable"]


def test_a_done_file_completes_the_unit_and_no_picture_is_detected_twice(
    settings, tmp_path: Path, pictures: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    shots = tmp_path / "shots"
    feeder = Feeder(shots / "CAM-1", pictures, then=lambda: (shots / "CAM-1" / "DONE").write_text(""))
    detected: list[Path] = []
    real_classify = image_outcomes.classify_file

    def counting(path, *args, **kwargs):  # every detection in this process, early or batch (jobs 1)
        detected.append(Path(path))
        return real_classify(path, *args, **kwargs)

    monkeypatch.setattr(image_outcomes, "classify_file", counting)
    feed_from_first_poll(monkeypatch, feeder)
    lines = station(settings, shots, ["CAM-1"], WatchRule(done_file="DONE", settle_s=0.0))
    assert [(r.status, r.views) for r in lines] == [(PASS, len(pictures))]
    if settings.jobs == 1:  # in this process: each picture detected once, as it landed
        assert sorted(p.name for p in detected) == [p.name for p in pictures]


class LockstepClock:
    """The station's clock and sleep: each sleep advances the clock by the poll and runs ``on_poll``."""

    def __init__(self, on_poll: Callable[[], None] = lambda: None) -> None:
        self.now, self.polls, self.on_poll = 0.0, 0, on_poll

    def clock(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.polls += 1
        self.now += seconds
        self.on_poll()


def test_a_picture_written_in_place_is_detected_only_once_its_size_settled(
    settings, tmp_path: Path, pictures: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "shots" / "CAM-1"
    shutil.copytree(pictures[0].parent, folder, ignore=shutil.ignore_patterns("*.json", pictures[-1].name))
    data = pictures[-1].read_bytes()
    chunks = [data[i : i + 4096] for i in range(0, len(data), 4096)]
    slow = (folder / pictures[-1].name).open("wb")  # the last picture, one chunk per poll

    def write_a_chunk() -> None:
        if chunks:
            slow.write(chunks.pop(0))
            slow.flush()
        elif not slow.closed:
            slow.close()

    write_a_chunk()
    started: list[tuple[str, int]] = []
    real_start = image_outcomes.start_file

    def spy(path: Path, *args, **kwargs):
        started.append((path.name, path.stat().st_size))
        return real_start(path, *args, **kwargs)

    monkeypatch.setattr(image_outcomes, "start_file", spy)
    steps = LockstepClock(write_a_chunk)
    monkeypatch.setattr(
        station_module, "watch_unit", functools.partial(watch_unit, clock=steps.clock, sleep=steps.sleep)
    )
    lines = station(settings, tmp_path / "shots", ["CAM-1"], WatchRule(views=len(pictures), settle_s=0.1))
    assert [(r.status, r.views) for r in lines] == [(PASS, len(pictures))]
    assert steps.polls > len(data) // 4096  # the station polled while the picture was half written
    assert (pictures[-1].name, len(data)) in started and len(started) == len(pictures)  # only whole
    with Store.open(settings.db_url) as store:
        same_capture(store.get_session(lines[0].session_id), batch_session(settings, folder))  # type: ignore[arg-type]


def test_a_unit_whose_pictures_stop_is_an_error_line_naming_how_many_arrived_and_nothing_is_stored(
    settings, tmp_path: Path, pictures: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    shots = tmp_path / "shots"
    (shots / "CAM-1").mkdir(parents=True)
    for p in pictures[:2]:
        shutil.copyfile(p, shots / "CAM-1" / p.name)
    (shots / "CAM-1" / "half.png").write_bytes(b"\x89PNG")  # still "being written": its size never settles
    grows = LockstepClock(lambda: (shots / "CAM-1" / "half.png").open("ab").write(b"x"))
    shutil.copytree(pictures[0].parent, shots / "CAM-2", ignore=shutil.ignore_patterns("*.json"))
    monkeypatch.setattr(
        station_module, "watch_unit", functools.partial(watch_unit, clock=grows.clock, sleep=grows.sleep)
    )
    lines = station(
        settings, shots, ["CAM-1", "CAM-2"], WatchRule(views=len(pictures), settle_s=0.1, unit_timeout_s=1.0)
    )
    assert [(r.serial, r.status) for r in lines] == [("CAM-1", ERROR), ("CAM-2", PASS)]
    assert lines[0].message == (
        f"no new picture in {shots}/CAM-1 for 1 s (--unit-timeout-s): 2 of {len(pictures)} "
        "arrived, 1 more still being written; nothing was stored"
    )
    assert "scan the serial again" in (lines[0].hint or "")
    with Store.open(settings.db_url) as store:
        assert [s.serial for s in store.list_sessions()] == ["CAM-2"]


def test_ctrl_c_while_waiting_for_pictures_cancels_the_unit_and_the_next_one_runs(
    settings, tmp_path: Path, pictures: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    shots = tmp_path / "shots"
    shutil.copytree(pictures[0].parent, shots / "CAM-2", ignore=shutil.ignore_patterns("*.json"))
    feeder = Feeder(shots / "CAM-1", pictures[:3], then=lambda: os.kill(os.getpid(), signal.SIGINT))

    feed_from_first_poll(monkeypatch, feeder)  # three pictures come, then the operator presses Ctrl-C
    lines = station(settings, shots, ["CAM-1", "CAM-2"], WatchRule(views=len(pictures), settle_s=0.0))
    assert [(r.serial, r.status) for r in lines] == [("CAM-1", CANCELLED), ("CAM-2", PASS)]
    assert (
        lines[0].message == "cancelled (Ctrl-C) while its images were awaited or detected; nothing was stored"
    )
    with Store.open(settings.db_url) as store:
        assert [s.serial for s in store.list_sessions()] == ["CAM-2"]


@pytest.mark.parametrize(
    ("rule", "template", "message"),
    [
        (WatchRule(), "{serial}", "--watch needs --views N or --done-file NAME"),
        (WatchRule(views=0), "{serial}", "--views must be 1 or more, got 0"),
        (WatchRule(done_file="sub/DONE"), "{serial}", "--done-file 'sub/DONE' must be a file name"),
        (WatchRule(done_file="last.png"), "{serial}", "--done-file 'last.png' must be a file name"),
        (WatchRule(views=3, settle_s=-1), "{serial}", "--settle-s must be 0 or more seconds, got -1"),
        (WatchRule(views=3, unit_timeout_s=0), "{serial}", "--unit-timeout-s must be a positive number"),
        (WatchRule(views=3), "{serial}/*.png", "is a glob"),
    ],
)
def test_a_watch_rule_that_cannot_work_is_a_usage_error_before_any_unit(
    sqlite_url: str, tmp_path: Path, rule: WatchRule, template: str, message: str
) -> None:
    settings = load_settings(db=sqlite_url, env={}, jobs=1)
    with pytest.raises(UsageError, match=message.replace("*", r"\*").replace(".", r"\.")):
        run_station(
            settings, StationRequest("A17", f"{tmp_path}/{template}", watch=rule), ["CAM-1"], lambda r: None
        )


def test_a_unit_path_that_is_a_file_is_an_error_line(settings, tmp_path: Path) -> None:
    (tmp_path / "CAM-1").write_text("a file, not the unit's folder")
    lines = station(settings, tmp_path, ["CAM-1"], WatchRule(views=3))
    assert [(r.status, r.message) for r in lines] == [
        (ERROR, f"{tmp_path}/CAM-1 is not a folder; --watch watches a folder per unit")
    ]


def test_with_the_store_away_a_watched_unit_is_queued_with_its_early_detections(
    tmp_path: Path, tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    central = central_folder(tmp_path)
    shots = unit_folders(tmp_path_factory, tmp_path)
    settings = load_settings(db=f"sqlite:///{central / 'calibctl.db'}", station="line-3", env={}, jobs=1)
    views = len(list((shots / "CAM-1").glob("*.png")))
    rule, spool = WatchRule(views=views, settle_s=0.0), tmp_path / "spool.sqlite"
    lines: list[UnitResult] = []
    run_station(
        settings,
        StationRequest("A17", f"{shots}/{{serial}}", spool=spool, watch=rule),
        ["CAM-1"],
        lines.append,
    )  # online: the spool remembers the board
    detected: list[str] = []
    real_classify = image_outcomes.classify_file

    def counting(path, *args, **kwargs):
        detected.append(Path(path).name)
        return real_classify(path, *args, **kwargs)

    monkeypatch.setattr(image_outcomes, "classify_file", counting)
    with away(central):
        run_station(
            settings,
            StationRequest("A17", f"{shots}/{{serial}}", spool=spool, watch=rule),
            ["CAM-2"],
            lines.append,
        )
    assert [(r.serial, r.status, r.verdict) for r in lines] == [
        ("CAM-1", PASS, None),
        ("CAM-2", QUEUED, PASS),
    ]
    assert lines[1].after_last_image_s is not None
    assert len(detected) == views  # each picture once, as it landed; the capture into the spool reused them
