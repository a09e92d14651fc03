"""A rendered 3-camera rig whose CAM2 exposes 30 ms after the others while its timestamps say it exposed with
them. With a board that sways, the pairs with CAM2 are named (rig-exposure-offset) with an offset near 30 ms
and CAM0 / CAM1 first; the pair CAM0-CAM1, exposed together, is not. With a board that drifts and turns
steadily the offset hides in the poses (the residual barely moves, CAM2 lands many sigma off); declared
(--exposure-offset CAM2=+30), CAM2's corners are interpolated to its listed times and the rig recovers the
truth within its sigma. Estimated from the data (--estimate-exposure-offset CAM2), the swaying board gives the
offset within its sd; the steady one cannot show it and the estimate is refused."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics.rig_frame_shift import DROP_NO_NEIGHBOUR
from calibctl.core.extrinsics.se3 import rotation_angle_deg
from calibctl.core.synth.pinhole import render_view
from calibctl.core.synth.rig import RigTruth, synthesize_rig
from calibctl.errors import NumericalError
from calibctl.workflows.rig.rig_folders import solve_rig_folders
from calibctl.workflows.rig.rig_video import EXPOSURE_OFFSET
from tests.core.rig_sessions import true_members

BOARD = BoardSpec.chessboard(9, 6, 0.025)
N_FRAMES = 11
PERIOD_S = 0.2  # between frames
SWAY_M, SWAY_PERIOD_S = 0.015, 2.4  # the board sways 15 mm either way: up to 39 mm/s
# Steady: 32 mm/s and 10 deg/s about an axis in the board's plane, so between neighbouring frames the corners
# move almost linearly in time, as interpolating them assumes.
VELOCITY_M_S = np.array([0.03, 0.01, 0.0])
TURN_DEG_S, TURN_AXIS = 10.0, np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
LAG_S = (0.0, 0.0, 0.030)  # CAM2 exposes 30 ms late; the timestamps do not say so
Z_MAX = 3.0


def _swayed(T_root_board: np.ndarray, t_s: float) -> np.ndarray:
    out = T_root_board.copy()
    phase = 2 * np.pi * t_s / SWAY_PERIOD_S
    out[:3, 3] += SWAY_M * np.array([np.sin(phase), 0.5 * np.cos(phase), 0.0])
    return out


def _drifted(T_root_board: np.ndarray, t_s: float) -> np.ndarray:
    out = T_root_board.copy()
    t_mid_s = t_s - N_FRAMES * PERIOD_S / 2
    turn, _ = cv2.Rodrigues(np.radians(TURN_DEG_S * t_mid_s) * TURN_AXIS)
    out[:3, :3] = T_root_board[:3, :3] @ turn
    out[:3, 3] += VELOCITY_M_S * t_mid_s
    return out


def _render(out: Path, motion: Callable[[np.ndarray, float], np.ndarray]) -> tuple[RigTruth, Path]:
    rng = np.random.default_rng(11)
    truth = synthesize_rig(3, BOARD, 1, rng, baselines_m=(0.08, 0.07))
    rows = ["sync_index,cam_id,frame_index,frame_time"]
    for f in range(N_FRAMES):
        t_s = f * PERIOD_S
        for c, name in enumerate(truth.names):
            T_root_board = motion(truth.T_root_board[0], t_s + LAG_S[c])
            T_cam_board = np.linalg.inv(truth.T_root_cam[c]) @ T_root_board
            gray = render_view(truth.cameras[c], BOARD, T_cam_board, rng, supersample=2)
            (out / name).mkdir(exist_ok=True)
            cv2.imwrite(str(out / name / f"f{f:03d}.png"), gray)
            rows.append(f"{f},{name},{f},{10.0 + t_s + 0.001 * c:.6f}")
    (out / "timestamps.csv").write_text("\n".join(rows) + "\n")
    return truth, out


@pytest.fixture(scope="module")
def swaying_rig(tmp_path_factory) -> tuple[RigTruth, Path]:
    return _render(tmp_path_factory.mktemp("swaying_rig"), _swayed)


@pytest.fixture(scope="module")
def drifting_rig(tmp_path_factory) -> tuple[RigTruth, Path]:
    return _render(tmp_path_factory.mktemp("drifting_rig"), _drifted)


def _solve(truth: RigTruth, out: Path, **kw):
    return solve_rig_folders(
        {name: out / name for name in truth.names},
        BOARD,
        intrinsics={m.name: m for m in true_members(truth)},
        timestamps=out / "timestamps.csv",
        time_tolerance_ms=6.0,
        **kw,
    )


def _z(truth: RigTruth, run) -> dict[str, tuple[float, float]]:
    """Each camera's error against the truth in its own sigmas: (baseline, rotation / sqrt(3))."""
    assert run.solution is not None
    out = {}
    for edge in run.solution.tree.edges:
        T_true = truth.T_root_cam[truth.names.index(edge.child)]
        err_mm = abs(edge.translation_mm - np.linalg.norm(T_true[:3, 3]) * 1e3)
        err_deg = rotation_angle_deg(edge.T_parent_child[:3, :3] @ T_true[:3, :3].T)
        out[edge.child] = (
            err_mm / edge.sigma_translation_mm,
            err_deg / (np.sqrt(3) * edge.sigma_rotation_deg),
        )
    return out


def test_the_late_camera_is_named_with_its_offset(swaying_rig):
    run = _solve(*swaying_rig)
    found = {f.message.split(":")[0]: f for f in run.findings if f.rule == EXPOSURE_OFFSET}
    assert set(found) == {"pair CAM0-CAM2", "pair CAM1-CAM2"}, run.findings
    for pair, finding in found.items():
        first = pair.split()[1].split("-")[0]
        said = re.search(rf"camera {first} exposed about (\d+) ms before camera CAM2", finding.message)
        assert said is not None, finding.message
        assert abs(int(said.group(1)) - 30) <= 10, finding.message
        assert finding.severity == "error" and "hold the board still" in finding.fix
        declare = re.search(r"--exposure-offset CAM2=\+(\d+)", finding.fix)
        assert declare is not None and abs(int(declare.group(1)) - 30) <= 10, finding.fix
    assert not run.passed


def test_a_declared_offset_recovers_the_truth_a_steady_motion_hides(drifting_rig):
    truth, out = drifting_rig
    as_timestamped = _solve(truth, out)
    assert max(_z(truth, as_timestamped)["CAM2"]) > 3 * Z_MAX  # the poses absorb the latency
    declared = _solve(truth, out, exposure_offsets_ms={"CAM2": LAG_S[2] * 1e3})
    assert not [f for f in declared.findings if f.rule == EXPOSURE_OFFSET]
    assert declared.timing is not None and declared.timing["exposure_offset_ms"] == {"CAM2": 30.0}
    # frame 0 has no earlier frame to interpolate from; every other rig frame keeps CAM2
    assert declared.timing["exposure_dropped"] == {"CAM2": {DROP_NO_NEIGHBOUR: 1}}
    for camera, z in _z(truth, declared).items():
        assert max(z) < Z_MAX, camera


def test_an_estimated_offset_lies_within_its_sd_of_the_truth(swaying_rig):
    run = _solve(*swaying_rig, estimate_offsets=["CAM2"])
    assert run.timing is not None
    (ms,), (sd_ms,) = run.timing["exposure_offset_ms"].values(), run.timing["exposure_offset_sd_ms"].values()
    assert 0 < sd_ms < 5.0
    assert abs(ms - LAG_S[2] * 1e3) < Z_MAX * sd_ms
    assert not [f for f in run.findings if f.rule == EXPOSURE_OFFSET]


def test_an_offset_a_steady_board_cannot_show_is_not_estimated(drifting_rig):
    with pytest.raises(NumericalError, match="CAM2's exposure offset cannot be estimated") as refused:
        _solve(*drifting_rig, estimate_offsets=["CAM2"])
    assert "--exposure-offset CAM2=MS" in (refused.value.hint or "")
