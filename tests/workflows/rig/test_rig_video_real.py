"""caliscope-4cam (../shared/datasets): four real webcams, one video each, an inverted ChArUco and the
recorder's timestamps; full resolution, so ``slow``. Every camera finds the board, the frames pair by time,
the rig is solved and every loop closure judged, camera 1 is named one frame off its timestamps, and the
poses land near the recorder's own (a peer's answer, not truth: benchmarks/results/rig_caliscope.md has the
numbers and why they differ). With camera 1's shift and camera 0's exposure offset declared, nothing is named
and every camera's joint residual falls below what the undeclared offset leaves."""

from __future__ import annotations

import os
import tomllib

import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics.se3 import invert, rotation_angle_deg
from calibctl.workflows.rig.rig_folders import solve_rig_folders
from tests.datasets import DATASETS

SET = DATASETS / "caliscope-4cam"
BOARD = BoardSpec.charuco(4, 5, 0.054, 0.054 * 0.75, "DICT_4X4_1000", inverted=True)
CAMS = ("0", "1", "2", "3")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def real_run():
    if not SET.is_dir():
        if os.environ.get("CI"):
            pytest.fail(f"caliscope-4cam not found at {SET}")
        pytest.skip(f"caliscope-4cam not found at {SET} (set CALIBCTL_TEST_DATASETS)")
    sources = {cam: SET / "extrinsic" / f"cam_{cam}.mp4" for cam in CAMS}
    return solve_rig_folders(
        sources, BOARD, timestamps=SET / "extrinsic" / "timestamps.csv", time_tolerance_ms=5.0
    )


def _recorder_T_0_c() -> dict[str, np.ndarray]:
    doc = tomllib.loads((SET / "camera_array.toml").read_text())
    T_cam_world = {}
    for cam in CAMS:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = doc["cameras"][cam]["rotation"], doc["cameras"][cam]["translation"]
        T_cam_world[cam] = T
    return {cam: T_cam_world["0"] @ invert(T_cam_world[cam]) for cam in CAMS}


def test_every_camera_sees_the_inverted_board_and_the_frames_pair_by_time(real_run):
    for cam in CAMS:
        assert sum(o.corner_ids is not None for o in real_run.outcomes[cam]) >= 10, cam
    timing = real_run.timing
    assert timing["index_offset"] == {cam: 26 for cam in CAMS}  # the recorder numbers frames 26..136
    assert timing["spread_ms"]["max"] <= 5.0 and timing["outside_tolerance"] > 0
    assert all(u.reason.startswith("outside-time-tolerance") for u in real_run.match.unmatched)


def test_the_rig_is_solved_every_loop_judged_and_the_verdict_named(real_run):
    assert real_run.gate.passed and real_run.solution is not None
    assert len(real_run.loops) == 7  # every simple cycle of the complete 4-camera graph
    assert all(np.isfinite(lc.mahalanobis) for lc in real_run.loops)
    if not real_run.passed:
        assert {f.rule for f in real_run.findings if f.severity == "error"}


def test_the_poses_land_near_the_recorders(real_run):
    recorder = _recorder_T_0_c()
    sol = real_run.solution
    for c, cam in enumerate(sol.views.cameras[1:], start=1):
        T, ref = sol.T_a_b(0, c), recorder[cam]
        assert abs(np.linalg.norm(T[:3, 3]) / np.linalg.norm(ref[:3, 3]) - 1) < 0.1, cam
        assert rotation_angle_deg(T[:3, :3] @ ref[:3, :3].T) < 6.0, cam


def test_camera_1_one_frame_off_its_timestamps_is_named(real_run):
    shifted = [f for f in real_run.findings if f.rule == "rig-frame-shift"]
    assert [f.message.split("'")[0] for f in shifted] == ["camera 1"]
    assert "1 frame later" in shifted[0].message and "--frame-shift 1=+1" in shifted[0].fix


def test_camera_0s_exposure_offset_declared_is_modelled(real_run):  # real_run: skips without the set
    sources = {cam: SET / "extrinsic" / f"cam_{cam}.mp4" for cam in CAMS}
    declared = solve_rig_folders(
        sources,
        BOARD,
        "opencv-default",
        timestamps=SET / "extrinsic" / "timestamps.csv",
        time_tolerance_ms=5.0,
        frame_shifts={"1": 1},
        exposure_offsets_ms={
            "0": -28.0
        },  # estimated -29.5 ms, sd 1.8 (bench_rig_caliscope.py --offset-scan 0)
    )
    assert not {"rig-frame-shift", "rig-exposure-offset"} & {f.rule for f in declared.findings}
    assert declared.timing["exposure_offset_ms"] == {"0": -28.0}
    assert sum(declared.timing["exposure_dropped"]["0"].values()) <= 5
    # declared, every camera's joint residual is under 0.7 px; as timestamped (shift declared) camera 0 left
    # 0.81 px and camera 3 1.24 px (benchmarks/results/rig_caliscope.md)
    assert declared.solution is not None and max(declared.solution.rms_px) < 0.7
