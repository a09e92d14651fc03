"""Capture as a library: what is stored and when, station overrides, stopping, sources and patterns."""

from __future__ import annotations

import datetime as dt
import json
import shutil
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.config import load_settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import DetectorSettings, detect_board
from calibctl.errors import InputError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.camera import capture as capture_workflow
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.camera import pattern_check
from calibctl.workflows.camera.capture import CaptureRequest, capture, parse_now
from tests.artifacts.factories import measured_board
from tests.datasets import BAKA_STEREO, needs_datasets
from tests.workflows.synth_folders import rendered

SERIAL = "CAM-0042"
CORNER_TRUTH_TOL_PX = 0.1  # the bar for detected vs rendered corners (mean)


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rendered(tmp_path_factory, "good")


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rendered(tmp_path_factory, "video") / "video.avi"


@pytest.fixture
def thread_workers(monkeypatch) -> None:
    """Detection on threads whatever the file count or a pool warm from an earlier test: what a test
    patches in this process reaches the workers."""
    from calibctl.core.capture import image_outcomes

    monkeypatch.setattr(image_outcomes, "PROCESS_MIN_FILES", 10**6)
    monkeypatch.setattr(image_outcomes.worker_pool, "is_warm", lambda workers: False)


@pytest.fixture
def settings(sqlite_url: str):
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return load_settings(db=sqlite_url, station="st-7", operator="op-ana", env={})


@pytest.fixture
def any_db_settings(db_url: str):
    """Settings on a SQLite file and on a fresh PostgreSQL database."""
    with Store.open(db_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    return load_settings(db=db_url, station="st-7", operator="op-ana", env={})


def test_folder_capture_stores_outcomes_corners_gates_and_images(any_db_settings, good: Path) -> None:
    settings = any_db_settings
    result = capture(settings, CaptureRequest(SERIAL, "A17", str(good)))
    truth = json.loads((good / "truth.json").read_text())
    with Store.open(settings.db_url) as store:
        stored = store.get_session(result.session.session_id)
        assert stored == result.session
        for o in stored.outcomes:
            assert store.image_path(o.sha256) is not None, o.name
    assert stored.status == "accepted" and stored.source_kind == "folder" and stored.image_size == (640, 480)
    assert stored.source == str(good.resolve())
    assert (stored.station, stored.operator, stored.serial, stored.board.ref) == (
        "st-7",
        "op-ana",
        SERIAL,
        "A17@1",
    )
    assert [o.name for o in stored.outcomes] == [v["file"] for v in truth["views"]]
    assert result.images_stored == len(stored.outcomes) == 12
    # a session that is not hopeless also carries the decisive projection gate
    assert {g.gate: g.passed for g in stored.gates} == {
        "observability": True,
        "tilt": True,
        "coverage": True,
        "views": True,
        "one_camera": True,
        "projection": True,
    }
    assert all(g.reason is None and g.hint is None for g in stored.gates)
    by_file = {v["file"]: np.array(v["corners_px"]) for v in truth["views"]}
    for view in stored.views:
        corners = np.array(view.corners_px, dtype=np.float64)
        error = np.linalg.norm(corners - by_file[view.name][view.corner_ids], axis=1)
        assert error.mean() < CORNER_TRUTH_TOL_PX, (view.name, error.mean())
        assert (
            15.0 < view.tilt_deg < 45.0 and view.tilt_direction is not None
        )  # the scene's tilts are 20-40 deg


def test_a_folder_capture_decodes_each_file_once_and_keeps_the_half_size_maximum(
    settings, good: Path, monkeypatch, thread_workers
) -> None:
    files = sorted(good.glob("*.png"))
    expected = None
    for path in files:  # what the capture kept before: a reduced decode of every file, then the maximum
        reduced = cv2.imread(str(path), cv2.IMREAD_REDUCED_GRAYSCALE_2)
        expected = reduced if expected is None else np.maximum(expected, reduced)
    decodes: list[int] = []
    real_imdecode = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a: decodes.append(1) or real_imdecode(*a))
    kept = {}
    real_collected = capture_workflow._Collected
    monkeypatch.setattr(
        capture_workflow, "_Collected", lambda *a, **k: kept.setdefault("got", real_collected(*a, **k))
    )
    capture(settings, CaptureRequest(SERIAL, "A17", str(good), jobs=2))
    # each file once for detection, plus the pattern check's probe pictures (read as bytes too, since a
    # cv2.imread of a name that is not UTF-8 crashed: docs/hardening.md)
    assert len(decodes) == len(files) + pattern_check.PROBE_IMAGES
    np.testing.assert_array_equal(kept["got"].max_gray, expected)


def test_station_file_overrides_the_gate_thresholds(sqlite_url: str, good: Path, tmp_path: Path) -> None:
    station_file = tmp_path / "station.yaml"
    station_file.write_text("gates: {observability_min: 1.0e-3, min_views: 13}\n", encoding="utf-8")
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    settings = load_settings(db=sqlite_url, station_config=station_file, env={})
    result = capture(settings, CaptureRequest(SERIAL, "A17", str(good)))
    gates = {g.gate: g for g in result.session.gates}
    assert result.session.status == "rejected"
    assert gates["observability"].threshold == 1e-3 and gates["observability"].reason == "observability.low"
    assert 1e-4 < gates["observability"].value < 1e-3  # passes the default, fails the station's threshold
    assert (
        gates["views"].threshold == 13
        and gates["views"].value == 12
        and gates["views"].reason == "views.too_few"
    )
    assert gates["coverage"].passed and gates["tilt"].passed


def _gates_raise(monkeypatch, error: BaseException) -> None:
    def broken(*args, **kwargs):
        raise error

    monkeypatch.setattr(capture_workflow, "evaluate_gates", broken)


def test_a_failure_before_the_session_write_leaves_no_session(settings, good: Path, monkeypatch) -> None:
    _gates_raise(monkeypatch, RuntimeError("power cut"))
    with pytest.raises(RuntimeError, match="power cut"):
        capture(settings, CaptureRequest(SERIAL, "A17", str(good)))
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == []
        assert store.counts()["images"] == 12  # written first: content-addressed, they expire


def test_video_frames_are_selected_and_kept_frames_stored_as_png(settings, video: Path) -> None:
    result = capture(settings, CaptureRequest(SERIAL, "A17", str(video)))
    truth = json.loads((video.parent / "truth.json").read_text())
    session = result.session
    assert session.source_kind == "video" and result.stop_reason == "end of the video"
    assert len(session.outcomes) == truth["video"]["n_frames"]
    kept = [o for o in session.outcomes if o.status == "accepted"]
    assert [o.name for o in kept] == [v.name for v in session.views]
    stills = {f"frame-{v['frame']:06d}" for v in truth["views"] if v["still"]}
    assert {v.name for v in session.views} <= stills  # only still frames are kept
    keys = {truth["views"][int(v.name.split("-")[1])]["key_pose"] for v in session.views}
    assert len(keys) == len(session.views)  # at most one frame per pause
    with Store.open(settings.db_url) as store:
        for view in session.views:
            png = store.image_path(view.image_sha256)
            assert png is not None and cv2.imread(str(png), cv2.IMREAD_GRAYSCALE).shape == (240, 320)
    assert result.images_stored == len(session.views)


def test_max_views_and_duration_stop_a_video(settings, video: Path) -> None:
    early = capture(settings, CaptureRequest(SERIAL, "A17", str(video), duration_s=2.0))
    assert early.stop_reason == "--duration 2 s reached"
    assert len(early.session.outcomes) == 20  # 10 fps video time, not wall time
    full = capture(settings, CaptureRequest(SERIAL, "A17", str(video)))
    assert full.passed and not early.passed
    capped = capture(settings, CaptureRequest(SERIAL, "A17", str(video), max_views=len(full.session.views)))
    assert capped.stop_reason == f"the gates passed with {len(full.session.views)} views (--max-views 8)"
    assert len(capped.session.outcomes) < len(full.session.outcomes)
    assert [v.name for v in capped.session.views] == [v.name for v in full.session.views]


def _session_numbers(result) -> tuple:
    session = result.session
    return (
        result.stop_reason,
        session.status,
        [o.model_dump() for o in session.outcomes],
        [(v.name, v.corner_ids, v.corners_px, v.image_sha256) for v in session.views],
        [(g.gate, g.passed, g.value) for g in session.gates],
    )


@pytest.mark.parametrize(
    "stop", [{}, {"max_views": 6}, {"duration_s": 4.2}], ids=["whole", "max-views", "duration"]
)
def test_a_video_gives_the_same_session_at_every_job_count(settings, video: Path, stop: dict) -> None:
    """Frames are detected ahead on threads from 2 jobs on (``_detected_frames``) and settled in order: every
    frame gets the one-thread detection, so the outcomes, views, corners and gates are the same at 1, 2 and 4
    jobs."""
    runs = {
        jobs: capture(settings, CaptureRequest(SERIAL, "A17", str(video), jobs=jobs, **stop))
        for jobs in (1, 2, 4)
    }
    one = _session_numbers(runs[1])
    assert one[2] and one[3]  # frames examined and views kept
    assert _session_numbers(runs[2]) == one and _session_numbers(runs[4]) == one


@needs_datasets
def test_a_video_of_real_photos_gives_the_same_session_at_every_job_count(settings, tmp_path: Path) -> None:
    """opencv-left-right's 13 left photos (not made by us), each held still for 6 frames of an MJPG video, as
    an operator pausing the board would: the threads' look-ahead keeps the one-thread session, frame for
    frame."""
    from tests.datasets import LEFT_RIGHT

    photos = sorted(LEFT_RIGHT.glob("left*.jpg"))
    first = cv2.imread(str(photos[0]))
    clip = tmp_path / "left.avi"
    writer = cv2.VideoWriter(
        str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (first.shape[1], first.shape[0])
    )
    for photo in photos:
        image = cv2.imread(str(photo))
        for _ in range(6):
            writer.write(image)
    writer.release()
    runs = {
        jobs: capture(settings, CaptureRequest(SERIAL, "A17", str(clip), jobs=jobs)) for jobs in (1, 2, 4)
    }
    one = _session_numbers(runs[1])
    assert len(one[2]) == 6 * len(photos) and len(one[3]) >= 8  # every frame judged; most poses kept
    assert _session_numbers(runs[2]) == one and _session_numbers(runs[4]) == one


class _InterruptedVideo:
    """A video source that raises KeyboardInterrupt (Ctrl-C) when frame ``at`` is due."""

    def __init__(self, path: Path, at: int) -> None:
        self.inner = sources.VideoFileSource(path)
        self.at = at

    def frames(self):
        for frame in self.inner.frames():
            if frame.index == self.at:
                raise KeyboardInterrupt
            yield frame

    def close(self) -> None:
        self.inner.close()


def test_ctrl_c_finishes_the_session_with_the_views_kept(settings, video: Path, monkeypatch) -> None:
    at = 35
    reference = capture(settings, CaptureRequest(SERIAL, "A17", str(video), duration_s=at / 10.0, jobs=1))
    monkeypatch.setattr(sources, "open_stream", lambda spec: _InterruptedVideo(video, at))
    result = capture(settings, CaptureRequest(SERIAL, "A17", str(video), jobs=1))
    assert result.interrupted
    n = len(reference.session.views)
    assert result.stop_reason == f"interrupted (Ctrl-C); the session was finished with the {n} view(s) kept"
    assert [v.name for v in result.session.views] == [v.name for v in reference.session.views]
    assert len(result.session.outcomes) == at
    with Store.open(settings.db_url) as store:
        assert store.get_session(result.session.session_id).status == result.session.status


def test_ctrl_c_with_frames_detected_ahead_keeps_the_frames_selected_before_it(
    settings, video: Path, monkeypatch
) -> None:
    """At 2 jobs up to 4 frames are read and detected ahead of the one being selected; Ctrl-C drops those (as
    a Ctrl-C a moment earlier would have) and finishes the session with the frames selected before them."""
    at = 35
    reference = capture(settings, CaptureRequest(SERIAL, "A17", str(video), duration_s=at / 10.0, jobs=1))
    monkeypatch.setattr(sources, "open_stream", lambda spec: _InterruptedVideo(video, at))
    result = capture(settings, CaptureRequest(SERIAL, "A17", str(video), jobs=2))
    assert result.interrupted and result.stop_reason.startswith(
        "interrupted (Ctrl-C); the session was finished"
    )
    outcomes = [o.model_dump() for o in result.session.outcomes]
    assert at - 2 * 2 <= len(outcomes) < at
    assert outcomes == [o.model_dump() for o in reference.session.outcomes][: len(outcomes)]
    kept = {o["name"] for o in outcomes}
    assert [v.name for v in result.session.views] == [
        v.name for v in reference.session.views if v.name in kept
    ]


def test_camera_reader_thread_yields_newest_frames_in_order_and_ends(video: Path) -> None:
    camera = sources.CameraSource(str(video), "camera test")  # cv2.VideoCapture reads a file like a device
    try:
        indices = [frame.index for frame in camera.frames()]
    finally:
        camera.close()
    assert indices and indices == sorted(set(indices))
    assert indices[-1] <= 73


def test_a_camera_that_stops_before_the_gates_pass_is_an_error_with_no_session(
    settings, video: Path, tmp_path, monkeypatch
) -> None:
    """The real reader thread on a clip of the first 12 frames (one key pose: the gates cannot pass): its
    reads fail at the clip's end as an unplugged camera's do, and the capture says so instead of judging the
    views."""
    clip = tmp_path / "clip.avi"
    reader = cv2.VideoCapture(str(video))
    writer = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (320, 240))
    for _ in range(12):
        ok, frame = reader.read()
        assert ok
        writer.write(frame)
    reader.release()
    writer.release()
    monkeypatch.setattr(sources, "open_stream", lambda spec: sources.CameraSource(str(clip), spec.label))
    with pytest.raises(InputError) as caught:
        capture(
            settings, CaptureRequest(SERIAL, "A17", "/dev/video5")
        )  # never opened: open_stream is the clip
    assert caught.value.message.startswith("camera /dev/video5 stopped delivering frames after ")
    assert (
        "(the gates had not passed): unplugged, or taken by another program?; no session was stored"
        in caught.value.message
    )
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == []


@pytest.mark.parametrize(("text", "kind"), [("/dev/video3", "camera"), ("0", "camera"), ("12", "camera")])
def test_cameras_are_recognised(text: str, kind: str) -> None:
    spec = sources.resolve_source(text)
    assert spec.kind == kind and spec.label == f"camera {text}"


def test_folders_videos_and_bad_sources(tmp_path: Path) -> None:
    (tmp_path / "clip.avi").write_bytes(b"x")
    (tmp_path / "one.png").write_bytes(b"x")
    assert sources.resolve_source(str(tmp_path)).kind == "folder"
    assert sources.resolve_source(str(tmp_path / "clip.avi")).kind == "video"
    with pytest.raises(UsageError, match="is a single image"):
        sources.resolve_source(str(tmp_path / "one.png"))
    with pytest.raises(InputError, match="does not exist"):
        sources.resolve_source(str(tmp_path / "nope"))


def test_near_patterns_start_with_the_transposed_one() -> None:
    assert pattern_check.near_patterns(8, 6) == [
        (6, 8),
        (9, 6),
        (7, 6),
        (8, 7),
        (8, 5),
        (9, 7),
        (7, 5),
        (9, 5),
        (7, 7),
    ]
    assert pattern_check.near_patterns(3, 2) == [(2, 3), (4, 2), (2, 2), (3, 3), (4, 3)]  # no side below 2


def test_larger_board_check_needs_two_hits(good: Path) -> None:
    samples = [(p.name, cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)) for p in sorted(good.glob("*.png"))[:3]]
    small = BoardSpec.chessboard(8, 6, 0.025)
    error = pattern_check.larger_board_error(small, "A8@1", "A8", samples)
    assert error is not None and "a 9x6 chessboard is found in" in error.message
    assert (
        pattern_check.larger_board_error(small, "A8@1", "A8", samples[:1]) is None
    )  # one image proves nothing
    assert pattern_check.larger_board_error(BoardSpec.chessboard(9, 6, 0.025), "A9@1", "A9", samples) is None


def test_larger_board_probe_is_skipped_only_when_every_probed_view_shows_its_margin(
    good: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    samples: list[pattern_check.Sample] = []
    for path in sorted(good.glob("*.png"))[:3]:
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        assert image is not None
        samples.append((path.name, image))
    right = BoardSpec.chessboard(9, 6, 0.025)
    corners: dict[str, np.ndarray] = {}
    for name, gray in samples:
        detection, why = detect_board(gray, right)
        assert detection is not None, why
        corners[name] = detection.corners_px
    calls: list[tuple[int, int]] = []
    real_found = pattern_check._found

    def counted(
        sample: pattern_check.Sample, pattern: tuple[int, int], spec: BoardSpec, settings: DetectorSettings
    ) -> bool:
        calls.append(pattern)
        return real_found(sample, pattern, spec, settings)

    monkeypatch.setattr(pattern_check, "_found", counted)
    assert pattern_check.larger_board_error(right, "A9@1", "A9", samples, corners) is None
    assert calls == []  # the margin is visible past every side in all 3: no detector probe
    assert (
        pattern_check.larger_board_error(right, "A9@1", "A9", samples, dict(list(corners.items())[:2]))
        is None
    )
    assert sorted(set(calls)) == [(9, 7), (10, 6)]  # a view without corners is a "maybe": the probe runs
    short = {name: c.reshape(6, 9, 2)[:, 1:].reshape(-1, 2) for name, c in corners.items()}  # an 8x6 part
    error = pattern_check.larger_board_error(BoardSpec.chessboard(8, 6, 0.025), "A8@1", "A8", samples, short)
    assert error is not None and "a 9x6 chessboard is found in" in error.message


@needs_datasets
def test_larger_board_check_names_the_whole_board_sb_sees() -> None:
    # baka-stereo's 7x10 board registered as 9x6: in these three left images the classic detector finds
    # neither 10x6 nor 9x7 in two of them (one more column or row), so the +1 probes alone miss it; SB grown
    # from a seed grid sees 10x7 and the classic detector confirms it
    names = ["left_001772846782141.jpg", "left_001772847170203.jpg", "left_001772859893197.jpg"]
    samples = [(name, cv2.imread(str(BAKA_STEREO / "left" / name), cv2.IMREAD_GRAYSCALE)) for name in names]
    error = pattern_check.larger_board_error(BoardSpec.chessboard(9, 6, 0.025), "A9@1", "A9", samples)
    assert error is not None and "a 10x7 chessboard is found in" in error.message
    assert error.hint is not None and error.hint.endswith("registered as 10x7")
    transposed = pattern_check.larger_board_error(BoardSpec.chessboard(6, 9, 0.025), "A6@1", "A6", samples)
    assert transposed is not None and "a 7x10 chessboard is found in" in transposed.message
    assert (
        pattern_check.larger_board_error(BoardSpec.chessboard(10, 7, 0.025), "A10@1", "A10", samples) is None
    )


def test_parse_now() -> None:
    assert parse_now("2026-04-30") == dt.datetime(2026, 4, 30, tzinfo=dt.UTC)
    assert parse_now("2026-04-30T14:00:00+02:00") == dt.datetime(2026, 4, 30, 12, tzinfo=dt.UTC)
    with pytest.raises(UsageError, match="not an ISO 8601 time"):
        parse_now("yesterday")


def test_folder_only_options_are_refused_before_anything_runs(settings, good: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(good, copy)
    with pytest.raises(UsageError, match="apply to video and camera sources"):
        capture(settings, CaptureRequest(SERIAL, "A17", str(copy), max_views=10))
    with pytest.raises(UsageError, match="is not a camera serial"):
        capture(settings, CaptureRequest("CAM 1", "A17", str(copy)))


def test_a_video_without_the_registered_pattern_names_what_is_visible(settings, video: Path) -> None:
    with Store.open(settings.db_url) as store:
        store.add_board(measured_board("B10x7").model_copy(update={"cols": 10, "rows": 7}))
    with pytest.raises(InputError) as info:
        capture(settings, CaptureRequest(SERIAL, "B10x7", str(video), duration_s=1.6))
    message = info.value.message
    assert (
        f"no 10x7 chessboard (board B10x7@1) was found in any of the 16 readable frames of {video}" in message
    )
    assert "a 9x6 chessboard is visible in frame-000000 and frame-000015" in message
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == [] and store.counts()["images"] == 0


@pytest.mark.parametrize("workers", [1, 2])
def test_ctrl_c_on_a_large_folder_cancels_the_pending_images_and_stores_nothing(
    settings, good: Path, tmp_path: Path, monkeypatch, workers: int, thread_workers
) -> None:
    """KeyboardInterrupt from the third detection: the queued images are never detected (only those
    already running finish), no session and no image is stored."""
    from calibctl.core.capture import image_outcomes

    folder = tmp_path / "large"
    folder.mkdir()
    views = sorted(good.glob("*.png"))
    for i in range(60):
        shutil.copy(views[i % len(views)], folder / f"img-{i:03d}.png")
    calls: list[int] = []
    lock = threading.Lock()
    # A detection started after the interrupt waits until capture has returned, so each worker can start
    # at most one more however slowly the calling thread runs (on a loaded machine it may run late).
    capture_returned = threading.Event()
    real_detect = image_outcomes.detect_board

    def interrupted(*args, **kwargs):
        with lock:
            calls.append(1)
            n = len(calls)
        if n == 3:
            raise KeyboardInterrupt
        if n > 3:
            capture_returned.wait(timeout=30)
        return real_detect(*args, **kwargs)

    monkeypatch.setattr(image_outcomes, "detect_board", interrupted)
    try:
        with pytest.raises(KeyboardInterrupt):
            capture(settings, CaptureRequest(SERIAL, "A17", str(folder), jobs=workers))
    finally:
        capture_returned.set()
    assert len(calls) <= 3 + workers  # of 60: the rest was cancelled
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == []
        assert store.counts()["images"] == 0


def _pool_sized_folder(good: Path, tmp_path: Path) -> Path:
    """40 copies of the good views: enough for the process pool (image_outcomes.PROCESS_MIN_FILES)."""
    folder = tmp_path / "large"
    folder.mkdir()
    views = sorted(good.glob("*.png"))
    for i in range(40):
        shutil.copy(views[i % len(views)], folder / f"img-{i:03d}.png")
    return folder


@pytest.mark.parametrize("jobs", [2, 4])
def test_ctrl_c_during_a_capture_on_worker_processes_stores_nothing(
    settings, good: Path, tmp_path: Path, jobs: int
) -> None:
    """Ctrl-C arrives in the capturing process (workers ignore SIGINT) while processes detect: it
    propagates, no session and no image is stored, and the next capture on the warm pool works."""
    folder = _pool_sized_folder(good, tmp_path)

    class CtrlC(capture_workflow.CaptureObserver):
        def image_done(self, done: int, total: int, name: str, status: str) -> None:
            if done == 5:
                raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        capture(settings, CaptureRequest(SERIAL, "A17", str(folder), jobs=jobs), CtrlC())
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == [] and store.counts()["images"] == 0
    result = capture(settings, CaptureRequest(SERIAL, "A17", str(good), jobs=jobs))
    assert result.session.status == "accepted"


def test_a_capture_stores_the_same_session_at_every_job_count(settings, good: Path) -> None:
    sessions = [
        capture(settings, CaptureRequest(SERIAL, "A17", str(good), jobs=jobs)).session for jobs in (1, 2, 4)
    ]
    first = sessions[0]
    for other in sessions[1:]:
        assert [o.model_dump() for o in other.outcomes] == [o.model_dump() for o in first.outcomes]
        assert [v.model_dump() for v in other.views] == [
            v.model_dump() for v in first.views
        ]  # corners as floats
        assert [g.model_dump() for g in other.gates] == [g.model_dump() for g in first.gates]


# the images stored beside the gates (workflows.camera.image_writes)
# ------------------------------------------


def test_a_folders_images_are_stored_beside_the_gates_and_durable_before_its_session(
    settings, good: Path, monkeypatch
) -> None:
    """The writes run on their own thread while the gates run (they wait here until the gates have started:
    a capture that stored its images before the gates would time out below), and every image has its row
    and its file when the session is stored."""
    gates_started = threading.Event()
    writers, waited = [], []
    real_put, real_gates, real_add = Store.put_images, capture_workflow.evaluate_gates, Store.add_session

    def put_images(self, images, **kwargs):
        writers.append(threading.current_thread().name)
        waited.append(gates_started.wait(timeout=30))  # a deadlock guard, not a time limit on the test
        return real_put(self, images, **kwargs)

    def evaluate_gates(*args, **kwargs):
        gates_started.set()
        return real_gates(*args, **kwargs)

    def add_session(self, session):
        missing = [o.name for o in session.outcomes if o.sha256 and self.image_path(o.sha256) is None]
        assert missing == [], f"session stored before its images: {missing}"
        return real_add(self, session)

    monkeypatch.setattr(Store, "put_images", put_images)
    monkeypatch.setattr(capture_workflow, "evaluate_gates", evaluate_gates)
    monkeypatch.setattr(Store, "add_session", add_session)
    result = capture(settings, CaptureRequest(SERIAL, "A17", str(good), jobs=1))
    assert waited == [True] and writers[0].startswith("calibctl-image-writes")
    assert result.images_stored == 12 and result.session.status == "accepted"
    with Store.open(settings.db_url) as store:
        assert [s.session_id for s in store.list_sessions()] == [result.session.session_id]


def _image_store_full(monkeypatch) -> None:
    """Every image file write fails the way a full disk fails it (store.images, under file_errors)."""
    import errno
    import os

    from calibctl.store import images

    def full(path, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(images, "_link_anonymous", full)


@pytest.mark.parametrize("gates_fail", [False, True])
def test_a_full_image_store_is_the_error_and_no_session_is_stored(
    settings, good: Path, monkeypatch, gates_fail: bool
) -> None:
    """As when the images were stored before the gates: the writes' failure is the one raised, even when
    the gates then fail too (their error comes second in that order)."""
    from calibctl.errors import FileSystemError

    _image_store_full(monkeypatch)
    if gates_fail:
        _gates_raise(monkeypatch, InputError("the gates broke"))
    with pytest.raises(FileSystemError, match="no space left on the device"):
        capture(settings, CaptureRequest(SERIAL, "A17", str(good)))
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == [] and store.counts()["images"] == 0


def test_ctrl_c_during_the_gates_stops_the_writes_after_the_batch_in_progress(
    settings, good: Path, tmp_path: Path, monkeypatch
) -> None:
    """24 images, two batches: Ctrl-C in the gates while the first batch is being written. That batch
    commits whole (one transaction), the second is never written, no session is stored, and every row has
    its file."""
    folder = tmp_path / "two-batches"
    folder.mkdir()
    views = sorted(good.glob("*.png"))
    for i in range(2 * len(views)):
        shutil.copy(views[i % len(views)], folder / f"img-{i:03d}.png")
    stops: list[threading.Event] = []
    batches: list[int] = []
    real_store, real_put = capture_workflow._store_images, Store.put_images

    def store_images(store, settings, readable, where, stop):
        stops.append(stop)
        return real_store(store, settings, readable, where, stop)

    def put_images(self, images, **kwargs):
        stops[0].wait(timeout=30)  # until Ctrl-C has reached the writes (a deadlock guard, not a time limit)
        batches.append(len(set(images)))
        return real_put(self, images, **kwargs)

    monkeypatch.setattr(capture_workflow, "_store_images", store_images)
    monkeypatch.setattr(Store, "put_images", put_images)
    _gates_raise(monkeypatch, KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt):
        capture(settings, CaptureRequest(SERIAL, "A17", str(folder), jobs=1))
    assert stops[0].is_set() and len(batches) == 1 and capture_workflow.IMAGE_BATCH < 24
    with Store.open(settings.db_url) as store:
        files = [p.name for p in store.image_dir.rglob("*") if p.is_file()]
        assert store.list_sessions() == [] and store.counts()["images"] == len(files) == batches[0]
        assert all(store.image_path(name) is not None for name in files)


def test_a_detection_worker_killed_mid_capture_is_a_clear_error_and_stores_nothing(
    settings, good: Path, tmp_path: Path
) -> None:
    """The out-of-memory killer (or a crash in a decoder) takes a worker process while the pool detects: the
    capture ends with WorkerDiedError (exit 2) naming the images not detected, nothing is stored, and the next
    capture gets a fresh pool."""
    import os
    import signal

    from calibctl.core.capture import worker_pool
    from calibctl.errors import WorkerDiedError

    folder = _pool_sized_folder(good, tmp_path)

    class KillWorkers(capture_workflow.CaptureObserver):
        def image_done(self, done: int, total: int, name: str, status: str) -> None:
            if done == 5:
                for pid in list(worker_pool.process_pool(2)._processes):  # noqa: SLF001 - the test's stand-in for the OOM killer
                    os.kill(pid, signal.SIGKILL)

    with pytest.raises(
        WorkerDiedError, match=r"worker process died .* not yet detected: img-\d{3}\.png"
    ) as died:
        capture(settings, CaptureRequest(SERIAL, "A17", str(folder), jobs=2), KillWorkers())
    assert died.value.exit_code == 2
    with Store.open(settings.db_url) as store:
        assert store.list_sessions() == [] and store.counts()["images"] == 0
    assert capture(settings, CaptureRequest(SERIAL, "A17", str(good), jobs=2)).session.status == "accepted"
