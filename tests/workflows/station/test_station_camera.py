"""`calibctl station --camera`: each unit captured live from the station's camera, held until its stream is
over, then stored or queued whole; an unplugged or missing camera and Ctrl-C leave nothing behind.

The unit's camera is the rendered video's frames (8 key poses at 320x240, 74 frames) served in order where
the station opens its device: a test never opens a real device node.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from calibctl.errors import DatabaseUnreachableError, UsageError
from calibctl.store.repository import Store
from calibctl.store.spool import Spool
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.station import station as station_module
from calibctl.workflows.station.station import (
    CANCELLED,
    ERROR,
    FAIL,
    PASS,
    QUEUED,
    SYNCED,
    LiveCamera,
    StationRequest,
    UnitResult,
    check_request,
    run_station,
)
from calibctl.workflows.station.watch import WatchRule
from tests.workflows.station.spool_setup import away
from tests.workflows.synth_folders import rendered

DEVICE = "/dev/video7"  # never opened: open_stream is replaced by the unit's camera below
VIDEO_VIEWS = 8  # the video's key poses: the gates pass with the last one


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rendered(tmp_path_factory, "video") / "video.avi"


class UnitCamera:
    """The video's frames in order, as the station's camera delivers them; the cable pulled after
    ``unplug_after`` frames, or a real SIGINT sent when frame ``ctrl_c_at`` is due."""

    def __init__(self, video: Path, unplug_after: int | None = None, ctrl_c_at: int | None = None) -> None:
        self.inner = sources.VideoFileSource(video)
        self.unplug_after, self.ctrl_c_at = unplug_after, ctrl_c_at

    def frames(self):
        for frame in self.inner.frames():
            if frame.index == self.unplug_after:
                return
            if frame.index == self.ctrl_c_at:
                os.kill(os.getpid(), signal.SIGINT)
            yield frame

    def close(self) -> None:
        self.inner.close()


@pytest.fixture
def cameras(monkeypatch, video: Path):
    """Plug units in: ``cameras(UnitCamera kwargs, ...)`` - one per unit, in order; records what was
    opened."""
    opened: list[sources.SourceSpec] = []

    def plug(*units: dict) -> list[sources.SourceSpec]:
        queue = [UnitCamera(video, **unit) for unit in units]

        def open_stream(spec: sources.SourceSpec) -> UnitCamera:
            opened.append(spec)
            return queue.pop(0)

        monkeypatch.setattr(sources, "open_stream", open_stream)
        return opened

    return plug


def run(settings, serials, camera: LiveCamera | None = None, spool: Path | None = None) -> list[UnitResult]:
    lines: list[UnitResult] = []
    request = StationRequest("A17", None, spool=spool, camera=camera or LiveCamera(DEVICE))
    summary = run_station(settings, request, serials, lines.append)
    assert summary.units == lines
    return lines


def stored(settings) -> tuple[list[str], dict[str, int]]:
    with Store.open(settings.db_url) as store:
        return [s.serial for s in store.list_sessions()], store.counts()


def test_a_unit_is_captured_live_until_the_gates_pass_then_stored_and_solved(settings, cameras) -> None:
    opened = cameras({}, {})
    lines = run(settings, ["CAM-1", "CAM-2"])
    assert [(r.serial, r.status, r.version, r.views) for r in lines] == [
        ("CAM-1", PASS, 1, VIDEO_VIEWS),
        ("CAM-2", PASS, 1, VIDEO_VIEWS),
    ]
    assert [(spec.kind, spec.text) for spec in opened] == [
        (sources.CAMERA, DEVICE)
    ] * 2  # opened once per unit
    # the stream's last frame (the one that passed the gates) to the verdict: the session's gates, store and
    # solve
    assert all(r.after_last_image_s is not None and 0.0 < r.after_last_image_s < r.unit_s for r in lines)
    with Store.open(settings.db_url) as store:
        session = store.list_sessions("CAM-1")[0]
        assert session.source_kind == "camera" and session.source == DEVICE and session.status == "accepted"
        assert all(v.image_sha256 and store.image_path(v.image_sha256) is not None for v in session.views)
        assert store.get_artifact("CAM-1", None).provenance.session_id == session.session_id


def test_duration_ends_a_unit_judged_with_the_views_kept(settings, cameras) -> None:
    cameras({})
    lines = run(settings, ["CAM-1"], LiveCamera(DEVICE, duration_s=3.5))  # video time: 10 fps, 35 frames
    assert lines[0].status == FAIL and lines[0].message.startswith("capture rejected: ")
    assert lines[0].views is not None and 0 < lines[0].views < VIDEO_VIEWS
    with Store.open(settings.db_url) as store:  # stored as rejected, as calibctl calibrate stores it
        assert [s.status for s in store.list_sessions("CAM-1")] == ["rejected"]


def test_a_camera_unplugged_mid_unit_is_an_error_line_with_nothing_stored_and_the_next_unit_runs(
    settings, cameras
) -> None:
    cameras({"unplug_after": 45}, {})
    lines = run(settings, ["CAM-1", "CAM-2"])
    assert [(r.serial, r.status) for r in lines] == [("CAM-1", ERROR), ("CAM-2", PASS)]
    assert lines[0].message.startswith(f"camera {DEVICE} stopped delivering frames after 45 frame(s), ")
    assert "the gates had not passed" in lines[0].message and "no session was stored" in lines[0].message
    assert "cable" in (lines[0].hint or "")
    serials, counts = stored(settings)
    assert (
        serials == ["CAM-2"] and counts["images"] == VIDEO_VIEWS
    )  # CAM-1's kept frames never reached the store


def test_a_missing_camera_is_an_error_line_naming_the_devices_present(settings) -> None:
    device = "/dev/video987"
    if Path(device).exists():
        pytest.skip(f"{device} exists on this machine: a test never opens a real device")
    lines = run(settings, ["CAM-1"], LiveCamera(device))
    assert lines[0].status == ERROR and lines[0].message.startswith(
        f"cannot open camera {device}: {device} does not exist (video devices present: "
    )
    assert "plug the camera in" in (lines[0].hint or "")
    assert stored(settings)[0] == []


def test_ctrl_c_while_the_camera_streams_cancels_the_unit_with_nothing_stored(settings, cameras) -> None:
    cameras({"ctrl_c_at": 30}, {})
    lines = run(settings, ["CAM-1", "CAM-2"])
    assert [(r.serial, r.status) for r in lines] == [("CAM-1", CANCELLED), ("CAM-2", PASS)]
    assert (
        lines[0].message
        == "cancelled (Ctrl-C) while its images were captured from the camera; nothing was stored"
    )
    serials, counts = stored(settings)
    assert serials == ["CAM-2"] and counts["images"] == VIDEO_VIEWS


def test_with_the_store_away_a_unit_is_queued_with_its_frames_then_synced(
    settings, cameras, central: Path, tmp_path: Path
) -> None:
    spool = tmp_path / "spool.sqlite"
    cameras({}, {}, {})
    assert [r.status for r in run(settings, ["CAM-1"], spool=spool)] == [PASS]  # the spool learns the board
    with away(central):
        queued = run(settings, ["CAM-2"], spool=spool)
    assert [(r.serial, r.status, r.verdict, r.spool_record) for r in queued] == [("CAM-2", QUEUED, PASS, 1)]
    with Spool.open(spool, station="line-3", store=settings.db_url) as opened:
        assert len(list(opened.image_dir.glob("??/*"))) == VIDEO_VIEWS  # the held frames, copied in
    lines = run(settings, ["CAM-3"], spool=spool)
    assert [(r.serial, r.status, r.version) for r in lines] == [("CAM-2", SYNCED, 1), ("CAM-3", PASS, 1)]
    with Store.open(settings.db_url) as store:
        session = store.get_session(queued[0].session_id or "")
        assert session.source_kind == "camera"
        assert all(store.image_path(v.image_sha256 or "") is not None for v in session.views)
        assert store.verify().problems == []


def test_a_store_lost_after_the_stream_queues_the_held_unit_without_capturing_it_again(
    settings, cameras, tmp_path: Path, monkeypatch
) -> None:
    opened = cameras({})

    def cut(settings, held) -> None:
        raise DatabaseUnreachableError("the store went away (test)")

    monkeypatch.setattr(station_module, "write_to_store", cut)
    lines = run(settings, ["CAM-1"], spool=tmp_path / "spool.sqlite")
    assert [(r.serial, r.status, r.verdict) for r in lines] == [("CAM-1", QUEUED, PASS)]
    assert "the store went away (test)" in lines[0].message
    assert len(opened) == 1  # the camera was streamed once: the frames held were queued
    assert stored(settings)[0] == []


@pytest.mark.parametrize(
    ("request_", "message"),
    [
        (StationRequest("A17", "shots/{serial}", camera=LiveCamera(DEVICE)), "the station takes one source"),
        (StationRequest("A17", None), "the station takes one source"),
        (
            StationRequest("A17", None, camera=LiveCamera("shots/{serial}")),
            "--camera shots/{serial} is not a camera",
        ),
        (StationRequest("A17", None, camera=LiveCamera(".")), r"--camera \. is not a camera"),
        (
            StationRequest("A17", None, watch=WatchRule(views=3), camera=LiveCamera(DEVICE)),
            "--watch waits for pictures",
        ),
        (
            StationRequest("A17", None, camera=LiveCamera(DEVICE, duration_s=0.0)),
            "--duration must be a positive",
        ),
    ],
    ids=["both", "neither", "missing-path", "a-folder", "watch", "duration"],
)
def test_a_camera_station_that_cannot_start_is_a_usage_error(request_: StationRequest, message: str) -> None:
    with pytest.raises(UsageError, match=message):
        check_request(request_)
