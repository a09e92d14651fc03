"""The IMU as the board's metric gauge, and the camera's fit to the IMU's motion: two checks a wrong
board size or wrong intrinsics cannot pass while the extrinsic still "converges".

Board scale. The accelerometer measures specific force f = R_wi^T (a_w - g_w) + b_a in m/s^2 whatever
size the board was registered at, while the camera's positions scale with the board. A board printed
at 50 mm and registered at 40 mm makes every camera position 0.8x its true value; the solve bends the
lever arm to reconcile the two (T_imu_cam's translation off by 0.2 m) and only the accelerometer RMS
says so, which cannot be judged alone (real IMUs vibrate: EuRoC's accel RMS is 12x its datasheet
noise). ``board_scale`` solves once more with s = true size / registered size as a state
(``SolveOptions.board_scale``: the corners see the board scaled by s), its one-sigma from the same
covariance and block jackknife as every other state. The gauge asks one question (is the board off by
more than a few percent?), so it is solved on at most ``GAUGE_FRAMES`` frames a camera (every k-th: the
whole motion, all the IMU samples) and without the jackknife; only a scale off 1 by more than
``gates.MIN_SCALE_ERROR`` can be refused, and only then is the jackknife run, so a refusal's sigma is
the honest one. A passed gauge's sigma is the white-noise one widened by the first solve's largest
jackknife widening (over-, never understated: about 3x on renders). EuRoC cam0: 15.7 -> 6.0 s of CPU.
A residual regression on the first solve cannot do this: that solve already bent its trajectory until
the accelerometer residual is orthogonal to the motion (measured: s = 1.002 on a 1.25x board).

Camera fit. Wrong intrinsics (a focal length 6 % off) leave the board scale near 1 (the depth error
is along one axis and the lever arm absorbs it) but the IMU's rotations then cannot carry the corners
the way the camera model projects them: the corners fit their own per-frame PnP poses (6 free states a
frame) much better than the one IMU trajectory. ``camera_fit`` compares the two robust corner sigmas as
an F ratio: (v_joint / v_pnp - 1) (n - p) / p with n corner coordinates and p = 6 per-frame pose states;
about 1 when the camera model is right (the PnP fit is better only by the states it spends), large
when it is not. The sigmas are median-based: outliers the solve leaves out count in neither. Beside it,
the excess in pixels, sqrt(v_joint - v_pnp n / (n - p)): with corners far more precise than the
trajectory model (noise-free rendered images: 0.03 px about PnP) F grows large on the spline's own
misfit (0.06 px), which is no lens error worth refusing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from calibctl.core.imu.model import project
from calibctl.core.imu.plain import BoardTrack
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples
from calibctl.core.imu.solve import ImuCameraSolution, SolveOptions, solve_imu_cameras

_MEDIAN_TO_SIGMA_2D = 1.0 / np.sqrt(2.0 * np.log(2.0))  # 2-D Gaussian: median |r| = 1.177 sigma


@dataclass(frozen=True)
class BoardScale:
    """scale: the board's true size over its registered size, as the accelerometer measures it.
    sigma: its one-sigma (widened by the jackknife where the residuals are correlated in time).
    inflation: that widening (>= 1)."""

    scale: float
    sigma: float
    inflation: float


@dataclass(frozen=True)
class CameraFit:
    """joint_sigma_px / pnp_sigma_px: robust corner sigmas about the IMU's trajectory and about each
    frame's own PnP pose. coordinates: n, the corner coordinates (2 per corner) of the PnP frames;
    pose_states: p, 6 per PnP frame. f_ratio: (v_joint / v_pnp - 1) (n - p) / p. excess_px: the joint
    sigma beyond what the per-frame poses' states explain, sqrt(max(v_joint - v_pnp n / (n - p), 0))."""

    joint_sigma_px: float
    pnp_sigma_px: float
    coordinates: int
    pose_states: int
    f_ratio: float
    excess_px: float


GAUGE_FRAMES = 400  # frames a camera the gauge solves on (module docstring)


def board_scale(
    imu: ImuSamples,
    cameras: Sequence[CameraFrames],
    noise: ImuNoise,
    options: SolveOptions,
    tracks: Sequence[BoardTrack],
    solutions: Sequence[ImuCameraSolution],
    rig: Sequence[np.ndarray | None] | None = None,
    refusable: float = 0.03,
) -> BoardScale:
    """One more solve with the board's scale as a state (one board for every camera), started where
    ``solutions`` started (their plain estimates), on every k-th frame, no k-fold; its jackknife only when
    the scale is off 1 by more than ``refusable`` (the gate's floor: below it nothing is refused)."""
    step = max(1, -(-max(len(c.t_s) for c in cameras) // GAUGE_FRAMES))
    picked = [_every(c, t, step) for c, t in zip(cameras, tracks, strict=True)]
    starts = [q.plain for q in solutions]

    def solve(blocks: int) -> ImuCameraSolution:
        gauge = replace(options, board_scale=True, folds=0, jackknife_blocks=blocks)
        return solve_imu_cameras(
            imu, [c for c, _ in picked], noise, gauge, [t for _, t in picked], starts, rig
        )[0]

    s = solve(0)
    if abs(s.board_scale - 1.0) > refusable:  # a refusal: the honest sigma, the jackknife's own widening
        s = solve(options.jackknife_blocks)
        widen, inflation = 1.0, s.sigma_inflation["board_scale"]  # already in s.covariance
    else:  # a pass whatever the sigma: the first solve's widest widening (over-, never understated)
        widen = inflation = max(max(q.sigma_inflation.values(), default=1.0) for q in solutions)
    i = s.state_names.index("board_scale")
    return BoardScale(s.board_scale, widen * float(np.sqrt(s.covariance[i, i])), inflation)


def _every(frames: CameraFrames, track: BoardTrack, step: int) -> tuple[CameraFrames, BoardTrack]:
    """Every ``step``-th frame and its PnP pose (indices renumbered)."""
    if step == 1:
        return frames, track
    kept = np.arange(0, len(frames.t_s), step)
    sub = replace(
        frames,
        t_s=frames.t_s[kept],
        object_points=tuple(frames.object_points[k] for k in kept),
        image_points=tuple(frames.image_points[k] for k in kept),
    )
    on = track.frame % step == 0
    return sub, BoardTrack(track.t_s[on], track.T_cam_w[on], track.frame[on] // step)


def pnp_residuals(frames: CameraFrames, track: BoardTrack) -> np.ndarray:
    """Every tracked frame's corners (N, 2) px about that frame's own PnP pose."""
    return np.concatenate(
        [
            frames.image_points[f]
            - project(
                frames.object_points[f] @ T[:3, :3].T + T[:3, 3], frames.camera_matrix, frames.dist_coeffs
            )
            for f, T in zip(track.frame, track.T_cam_w, strict=True)
        ]
    ).reshape(-1, 2)


def camera_fit(frames: CameraFrames, track: BoardTrack, solution: ImuCameraSolution) -> CameraFit:
    """The corners about the joint solve against their own per-frame PnP fit (module docstring)."""
    pnp = pnp_residuals(frames, track)
    joint = solution.residuals["corner_px"]
    v_pnp = (_MEDIAN_TO_SIGMA_2D * float(np.median(np.linalg.norm(pnp, axis=1)))) ** 2
    v_joint = (_MEDIAN_TO_SIGMA_2D * float(np.median(np.linalg.norm(joint, axis=1)))) ** 2
    n, p = 2 * pnp.shape[0], 6 * len(track.frame)
    if n <= p:
        return CameraFit(float(np.sqrt(v_joint)), float(np.sqrt(v_pnp)), n, p, float("nan"), float("nan"))
    f_ratio = (v_joint / max(v_pnp, 1e-18) - 1.0) * (n - p) / p
    excess = np.sqrt(max(v_joint - v_pnp * n / (n - p), 0.0))
    return CameraFit(float(np.sqrt(v_joint)), float(np.sqrt(v_pnp)), n, p, float(f_ratio), float(excess))
