"""A rendered 3-camera rig filming a board that sways smoothly: CAM2 exposes 30 ms after the others while its
timestamps say it exposed with them. The pairs with CAM2 are named (rig-exposure-offset) with an offset near
30 ms and CAM0 / CAM1 first; the pair CAM0-CAM1, exposed together, is not."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.synth.pinhole import render_view
from calibctl.core.synth.rig import RigTruth, synthesize_rig
from calibctl.workflows.rig.rig_folders import solve_rig_folders
from calibctl.workflows.rig.rig_video import EXPOSURE_OFFSET
from tests.core.rig_sessions import true_members

BOARD = BoardSpec.chessboard(9, 6, 0.025)
N_FRAMES = 11
PERIOD_S = 0.2  # between frames
SWAY_M, SWAY_PERIOD_S = 0.015, 2.4  # the board sways 15 mm either way: up to 39 mm/s
LAG_S = (0.0, 0.0, 0.030)  # CAM2 exposes 30 ms late; the timestamps do not say so


def _swayed(T_root_board: np.ndarray, t_s: float) -> np.ndarray:
    out = T_root_board.copy()
    phase = 2 * np.pi * t_s / SWAY_PERIOD_S
    out[:3, 3] += SWAY_M * np.array([np.sin(phase), 0.5 * np.cos(phase), 0.0])
    return out


@pytest.fixture(scope="module")
def swaying_rig(tmp_path_factory) -> tuple[RigTruth, Path]:
    rng = np.random.default_rng(11)
    truth = synthesize_rig(3, BOARD, 1, rng, baselines_m=(0.08, 0.07))
    out = tmp_path_factory.mktemp("swaying_rig")
    rows = ["sync_index,cam_id,frame_index,frame_time"]
    for f in range(N_FRAMES):
        t_s = f * PERIOD_S
        for c, name in enumerate(truth.names):
            T_root_board = _swayed(truth.T_root_board[0], t_s + LAG_S[c])
            T_cam_board = np.linalg.inv(truth.T_root_cam[c]) @ T_root_board
            gray = render_view(truth.cameras[c], BOARD, T_cam_board, rng, supersample=2)
            (out / name).mkdir(exist_ok=True)
            cv2.imwrite(str(out / name / f"f{f:03d}.png"), gray)
            rows.append(f"{f},{name},{f},{10.0 + t_s + 0.001 * c:.6f}")
    (out / "timestamps.csv").write_text("\n".join(rows) + "\n")
    return truth, out


def test_the_late_camera_is_named_with_its_offset(swaying_rig):
    truth, out = swaying_rig
    run = solve_rig_folders(
        {name: out / name for name in truth.names},
        BOARD,
        intrinsics={m.name: m for m in true_members(truth)},
        timestamps=out / "timestamps.csv",
        time_tolerance_ms=6.0,
    )
    found = {f.message.split(":")[0]: f for f in run.findings if f.rule == EXPOSURE_OFFSET}
    assert set(found) == {"pair CAM0-CAM2", "pair CAM1-CAM2"}, run.findings
    for pair, finding in found.items():
        first = pair.split()[1].split("-")[0]
        said = re.search(rf"camera {first} exposed about (\d+) ms before camera CAM2", finding.message)
        assert said is not None, finding.message
        assert abs(int(said.group(1)) - 30) <= 10, finding.message
        assert finding.severity == "error" and "hold the board still" in finding.fix
    assert not run.passed
