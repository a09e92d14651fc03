"""`calibctl rig capture --timestamps` (and `capture --rig`): the members' images pair up by the recorder's
times within the tolerance, as `rig solve-folders` pairs them; an image no other camera has within it is
reported, never paired; a video member, or a tolerance without timestamps, is refused and nothing is
stored."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.errors import NotFoundError
from calibctl.store.repository import Store
from calibctl.workflows.rig.rig_video import OUTSIDE_TOLERANCE
from tests.workflows.rig.test_rig_capture_jobs import _store
from tests.workflows.rig_folders_data import rendered_rig, rig_sources

RUNNER = CliRunner()
N_FRAMES = 8
LATE = 3  # CAM1's frame 3 is listed 20 ms late: outside a 5 ms tolerance


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


def _timestamps(path: Path) -> Path:
    rows = ["sync_index,cam_id,frame_index,frame_time"]
    for f in range(N_FRAMES):
        rows.append(f"{f},CAM0,{f},{10.0 + 0.2 * f:.4f}")
        rows.append(f"{f},CAM1,{f},{10.0 + 0.2 * f + (0.020 if f == LATE else 0.002):.4f}")
    path.write_text("\n".join(rows) + "\n")
    return path


def _capture(url: str, rig2: Path, *extra: str, command: tuple[str, ...] = ("rig", "capture", "R1")):
    args = ["--db", url, "--json", *command, "--board", "A17"]
    args += [*rig_sources(rig2), *extra]
    return RUNNER.invoke(app, args)


def _nothing_stored(url: str) -> None:
    with Store.open(url) as store:
        assert store.list_sessions() == []
        with pytest.raises(NotFoundError):
            store.get_rig_session("R1")


@pytest.mark.parametrize("command", [("rig", "capture", "R1"), ("capture", "--rig", "R1")])
def test_the_images_pair_by_time_and_a_late_one_is_reported(tmp_path, rig2, command):
    url = _store(tmp_path / "t.db", rig2)
    r = _capture(url, rig2, "--timestamps", str(_timestamps(tmp_path / "ts.csv")), command=command)
    assert r.exit_code == 0, r.output
    session = json.loads(r.stdout)["rig_session"]
    assert len(session["frames"]) == N_FRAMES - 1
    late = {u["camera"]: u["reason"] for u in session["unmatched"]}
    assert late == {"CAM0": OUTSIDE_TOLERANCE, "CAM1": OUTSIDE_TOLERANCE}
    assert all(set(f["images"]) == {"CAM0", "CAM1"} for f in session["frames"])


def test_a_wider_tolerance_pairs_the_late_image_too(tmp_path, rig2):
    url = _store(tmp_path / "w.db", rig2)
    ts = str(_timestamps(tmp_path / "ts.csv"))
    r = _capture(url, rig2, "--timestamps", ts, "--time-tolerance-ms", "25")
    assert r.exit_code == 0, r.output
    session = json.loads(r.stdout)["rig_session"]
    assert len(session["frames"]) == N_FRAMES and session["unmatched"] == []


def test_a_tolerance_without_timestamps_is_refused_and_nothing_stored(tmp_path, rig2):
    url = _store(tmp_path / "n.db", rig2)
    r = _capture(url, rig2, "--time-tolerance-ms", "5")
    assert r.exit_code == 2, r.output
    assert "--time-tolerance-ms pairs frames by time: give the recorder's --timestamps" in r.output
    _nothing_stored(url)


def test_a_timestamps_file_naming_an_unknown_camera_is_refused_and_nothing_stored(tmp_path, rig2):
    url = _store(tmp_path / "u.db", rig2)
    ts = tmp_path / "ts.csv"
    ts.write_text("sync_index,cam_id,frame_index,frame_time\n0,CAM0,0,1.0\n0,CAM1,0,1.0\n0,CAM9,0,1.0\n")
    r = _capture(url, rig2, "--timestamps", str(ts))
    assert r.exit_code == 2, r.output
    assert f"{ts} names camera CAM9, which is not one of the rig's cameras (CAM0, CAM1)" in r.output
    _nothing_stored(url)


def test_a_video_member_with_timestamps_is_refused_and_nothing_stored(tmp_path, rig2):
    url = _store(tmp_path / "v.db", rig2)
    video = tmp_path / "CAM1.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 6.0, (64, 48), False)
    writer.write(np.zeros((48, 64), np.uint8))
    writer.release()
    args = ["--db", url, "rig", "capture", "R1", "--board", "A17", *rig_sources(rig2, video)]
    args += ["--timestamps", str(_timestamps(tmp_path / "ts.csv"))]
    r = RUNNER.invoke(app, args)
    assert r.exit_code == 2, r.output
    assert "rig capture pairs photos by time, but the source of CAM1 is a video" in r.output
    assert "rig solve-folders --timestamps" in r.output
    _nothing_stored(url)
