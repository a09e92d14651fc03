"""calibctl rig solve-folders from videos: bad input exits 2 with one line naming the file and the fix, and
nothing is written (videos of different lengths, a timestamps file naming an unknown camera, frames past
the end, duplicated timestamps, an undecodable video, a declared board that finds nothing)."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.synth.pinhole import PinholeCamera, render_view
from calibctl.core.synth.scenes import place_board, tilt_rotation

INVERTED = BoardSpec.charuco(5, 7, 0.03, 0.0225, "DICT_4X4_1000", inverted=True)
CHARUCO = ["--kind", "charuco", "--cols", "4", "--rows", "6", "--square-mm", "30", "--marker-mm", "22.5"]
CHARUCO += ["--dictionary", "DICT_4X4_1000"]
HEAD = "sync_index,cam_id,frame_index,frame_time\n"


def _video(path: Path, frames: list[np.ndarray], fps: float = 6.0) -> Path:
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (width, height), False)
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


@pytest.fixture(scope="module")
def videos(tmp_path_factory) -> Path:
    """A.avi and B.avi: 3 frames each of an inverted ChArUco board at 6 fps; C.avi: 4 frames (a different
    length); D.avi: 3 frames at 10 fps."""
    out = tmp_path_factory.mktemp("videos")
    camera = PinholeCamera.seed_reference()
    rng = np.random.default_rng(4)
    frames = [
        render_view(
            camera,
            INVERTED,
            place_board(camera, INVERTED, tilt_rotation(math.radians(20), k, 0.1), (320.0, 240.0), 0.5),
            rng,
            supersample=2,
        )
        for k in range(4)
    ]
    _video(out / "A.avi", frames[:3])
    _video(out / "B.avi", frames[1:4])
    _video(out / "C.avi", frames)
    _video(out / "D.avi", frames[:3], fps=10.0)
    (out / "broken.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42 this is not a video" * 20)
    return out


@pytest.fixture
def run(tmp_path):
    runner = CliRunner()

    def invoke(*args: str):
        result = runner.invoke(
            app, ["--db", f"sqlite:///{tmp_path / 'none.db'}", "rig", "solve-folders", *args]
        )
        return result

    return invoke


def _sources(videos: Path, *names: str) -> list[str]:
    return [a for n in names for a in ("--source", f"{n}={videos / (n + '.avi')}")]


def _refused(result, *words: str) -> None:
    assert result.exit_code == 2, result.output
    error = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(error) == 1, result.output
    for word in words:
        assert word in result.output, result.output


def test_videos_of_different_lengths_without_timestamps_are_refused(run, videos, tmp_path):
    result = run(*_sources(videos, "A", "C"), *CHARUCO, "--inverted", "--export-dir", str(tmp_path / "out"))
    _refused(result, "different lengths", "A.avi: 3", "C.avi: 4", "--timestamps")
    assert not (tmp_path / "out").exists()


def test_videos_of_different_frame_rates_without_timestamps_are_refused(run, videos):
    result = run(*_sources(videos, "A", "D"), *CHARUCO, "--inverted")
    _refused(result, "different frame rates", "A.avi: 6.0 fps", "D.avi: 10.0 fps", "--timestamps")


def test_a_timestamps_file_naming_an_unknown_camera_is_refused(run, videos, tmp_path):
    ts = tmp_path / "ts.csv"
    ts.write_text(HEAD + "0,A,0,1.0\n0,B,0,1.001\n0,Z,0,1.002\n")
    result = run(*_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--timestamps", str(ts))
    _refused(
        result, f"{ts} names camera Z, which is not one of the rig's cameras (A, B)", "--source 0=cam_0.mp4"
    )


def test_a_timestamps_file_with_frames_past_the_end_is_refused(run, videos, tmp_path):
    ts = tmp_path / "ts.csv"
    rows = [f"{i},{c},{i},{1.0 + i / 6 + k / 1e3}" for i in (0, 1, 2, 5) for k, c in enumerate("AB")]
    ts.write_text(HEAD + "\n".join(rows) + "\n")
    result = run(*_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--timestamps", str(ts))
    _refused(result, f"{ts} lists frame 5 of camera A", "has 3 frames (0..2): frames past the end")


def test_duplicated_timestamps_are_refused(run, videos, tmp_path):
    ts = tmp_path / "ts.csv"
    ts.write_text(HEAD + "0,A,0,1.0\n1,A,1,1.0\n0,B,0,1.001\n")
    result = run(*_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--timestamps", str(ts))
    _refused(
        result, "camera A frames 0 and 1 have the same time", "duplicated timestamps", "fix the recorder"
    )


def test_an_undecodable_video_is_refused_by_name(run, videos):
    result = run("--source", f"A={videos / 'A.avi'}", "--source", f"X={videos / 'broken.mp4'}", *CHARUCO)
    _refused(result, f"camera X: cannot decode the video {videos / 'broken.mp4'}", "ffmpeg")


def test_a_board_declared_without_its_inversion_is_named_with_what_was_seen(run, videos):
    result = run(*_sources(videos, "A", "B"), *CHARUCO)
    _refused(
        result,
        "camera A: the declared board is found on none of the 3 frames",
        "0 markers with DICT_4X4_1000 normal",
        "declare --inverted",
    )


def test_a_variant_on_a_chessboard_is_a_usage_error(run, videos):
    result = run(*_sources(videos, "A", "B"), "--cols", "9", "--rows", "6", "--square-mm", "25", "--inverted")
    _refused(result, "describe a ChArUco board")


def test_a_frame_shift_that_is_not_a_whole_number_is_refused(run, videos):
    result = run(*_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--frame-shift", "B=half")
    _refused(result, "--frame-shift B=half", "SERIAL=N")


def test_a_frame_shift_naming_an_unknown_camera_is_refused(run, videos, tmp_path):
    ts = tmp_path / "ts.csv"
    ts.write_text(
        HEAD
        + "".join(
            f"{i},{c},{i},{10 + i * 0.2 + d:.4f}\n" for i in range(3) for c, d in (("A", 0), ("B", 0.001))
        )
    )
    result = run(
        *_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--timestamps", str(ts), "--frame-shift", "Z=1"
    )
    _refused(result, "--frame-shift names camera Z", "A, B")


def test_a_frame_shift_on_photo_folders_is_refused(run, tmp_path):
    for name in ("L", "R"):
        (tmp_path / name).mkdir()
    args = ["--source", f"L={tmp_path / 'L'}", "--source", f"R={tmp_path / 'R'}", *CHARUCO]
    result = run(*args, "--frame-shift", "R=1")
    _refused(result, "--frame-shift applies to frames paired by time")


def _timestamps(tmp_path: Path) -> Path:
    """A and B's three frames 200 ms apart, B 1 ms after A."""
    ts = tmp_path / "ts.csv"
    rows = [f"{i},{c},{i},{10 + i * 0.2 + d:.4f}\n" for i in range(3) for c, d in (("A", 0), ("B", 0.001))]
    ts.write_text(HEAD + "".join(rows))
    return ts


@pytest.mark.parametrize("value", ["B=late", "B=nan", "B", "=30"])
def test_an_exposure_offset_that_is_not_a_number_is_refused(run, videos, value):
    result = run(*_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--exposure-offset", value)
    _refused(result, f"--exposure-offset {value}", "SERIAL=MS")


@pytest.mark.parametrize(
    ("value", "says"),
    [
        ("Z=30", ("--exposure-offset names camera Z", "A, B")),
        ("B=+250", ("--exposure-offset B=+250", "200.0 ms apart", "a whole frame or more")),
    ],
)
def test_an_exposure_offset_for_no_camera_or_past_a_frame_is_refused(run, videos, tmp_path, value, says):
    ts = _timestamps(tmp_path)
    args = [*_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--timestamps", str(ts)]
    _refused(run(*args, "--exposure-offset", value), *says)


def test_an_exposure_offset_on_photo_folders_is_refused(run, tmp_path):
    for name in ("L", "R"):
        (tmp_path / name).mkdir()
    args = ["--source", f"L={tmp_path / 'L'}", "--source", f"R={tmp_path / 'R'}", *CHARUCO]
    _refused(run(*args, "--exposure-offset", "R=30"), "--exposure-offset applies to frames paired by time")


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--estimate-exposure-offset", "Z"], ("--estimate-exposure-offset names camera Z", "A, B")),
        (
            ["--estimate-exposure-offset", "B", "--exposure-offset", "B=30"],
            ("camera B's exposure offset is both declared and to be estimated",),
        ),
    ],
)
def test_an_offset_to_estimate_for_no_camera_or_declared_too_is_refused(run, videos, tmp_path, extra, says):
    ts = _timestamps(tmp_path)
    _refused(run(*_sources(videos, "A", "B"), *CHARUCO, "--inverted", "--timestamps", str(ts), *extra), *says)
