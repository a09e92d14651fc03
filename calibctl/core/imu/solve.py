"""Camera-IMU calibration as one joint least-squares problem: T_imu_cam, td_s, gravity, biases.

States: T_imu_cam (rotation 3 as a left perturbation in the IMU frame, translation 3, m), td_s
(t_imu = t_cam + td_s; Kalibr's ``timeshift_cam_imu`` has the same sign), optionally a rolling-shutter
line delay (s per row, rows counted from the principal point's c_y), the gravity direction in the
board frame (2), a constant gyro bias (3) and accelerometer bias (3) (or, with ``bias_walk``, each a
random walk: a spline beside the trajectory's, eliminated with it), optionally the IMU's own
scale, misalignment and g-sensitivity (24, ``core.imu.intrinsics``, with weak priors), optionally the
board's true / registered size (``board_scale``, ``core.imu.metric``); plus the
nuisance IMU trajectory, a uniform cubic B-spline of the IMU pose (``core.imu.model``; knot spacing
``knot_spacing_s``). The camera intrinsics are held. Residuals: every corner's reprojection (px,
/ sigma_px), every IMU sample's gyro and accelerometer residual (/ the Kalibr density * sqrt(rate)),
the IMU model's priors, and with ``bias_walk`` each walk's increments (/ random_walk * sqrt(knot spacing)).

The solver is ``core.lm.solve_lm`` over the shared states only: each evaluation eliminates the spline
(its normal equations are block-banded, ``core.imu.spline.BandedCholesky``), exactly as the Schur path
eliminates per-view board poses, and hands LM the reduced system S = A - B C^-1 B^T, g - B C^-1 g_b;
a step moves the spline by the back-substitution C^-1 (g_b - B^T delta). S^-1 at the solution is the
marginal covariance of the shared states (the spline integrated out). Jacobians: central differences
on the per-sample local control points and the shared states (each corner's through its camera pose,
so the expensive part runs once per frame), analytic only for the lens' 6-dof pose chain.

Weights: corners start at ``corner_sigma_px`` (or 0.5 px), the IMU at its densities; after a first
solve corners over ``OUTLIER_SIGMAS`` robust sigmas (median-based) are left out, each group's
variance is re-estimated (corners: the RMS; IMU groups: raised, never lowered, to their RMS) and the
problem solved again, so the reported sigmas carry the residuals actually seen.

Uncertainty: S^-1 is right for white residuals (the renders: z-scores over 60 seeds have sd 0.9-1.1).
Real residuals are correlated in time (vibration, a lens error that follows the board), so a
delete-one-block jackknife (``jackknife_blocks`` contiguous blocks) runs beside it and a state's sigma
is widened to the jackknife's where that variance is over ``JACKKNIFE_RATIO`` times larger
(benchmarks/results/imu.md: EuRoC's quarters scatter 4-13x beyond the white-noise rotation sigma).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.imu import intrinsics, model
from calibctl.core.imu.plain import BoardTrack, PlainResult, board_track, plain_calibration
from calibctl.core.imu.samples import CameraFrames, ImuInputError, ImuNoise, ImuSamples
from calibctl.core.imu.spline import BandedCholesky, Knots, local_controls, scatter_band, segment_gram
from calibctl.core.lm import Damping, DenseSystem, solve_lm

SHARED_NAMES = (
    "rot_x",
    "rot_y",
    "rot_z",
    "t_x",
    "t_y",
    "t_z",
    "td",
    "line_delay",
    "grav_a",
    "grav_b",
    "bg_x",
    "bg_y",
    "bg_z",
    "ba_x",
    "ba_y",
    "ba_z",
    "dbg_x",
    "dbg_y",
    "dbg_z",
    "dba_x",
    "dba_y",
    "dba_z",
    *intrinsics.NAMES,
    "board_scale",
)
CAMERA_STATES = 8  # the first eight shared names are each camera's own: T_imu_cam, td, line delay
INTRINSICS = slice(22, 22 + len(intrinsics.NAMES))  # the IMU model's states (core.imu.intrinsics)
BOARD_SCALE = INTRINSICS.stop  # true board size / registered size (``board_scale``; core.imu.metric)
H_CTRL = 1e-6  # central-difference steps: control points (rad, m), extrinsic (rad, m), time (s)
H_TIME = 1e-6
H_GRAV = 1e-6
MAX_TURN_RAD = 2.6  # the rotation-vector spline about the middle pose stays clear of its pi singularity
OUTLIER_SIGMAS = 5.0  # a corner this many robust sigmas off (2-D) after the first solve is left out
# The jackknife variance is biased upward (Efron-Stein) and noisy with ten blocks; a state's sigma is
# widened to the jackknife's only when the jackknife variance exceeds its white-noise variance this many
# times (the residuals are then correlated in time: real data, not the renders).
JACKKNIFE_RATIO = 4.0
BAND_FLOOR = 1e-9  # relative floor on the spline's diagonal (a knot only the end margin touches)


@dataclass(frozen=True)
class SolveOptions:
    """knot_spacing_s: spline knot spacing. corner_sigma_px: the corner noise to start from (the
    estimate replaces it unless ``fix_corner_sigma``). fix_imu_sigma: keep the IMU at the noise file's
    densities (not raised to its residuals; with ``fix_corner_sigma`` and 1 px, Kalibr's weighting).
    estimate_line_delay: add the rolling-shutter line delay. bias_drift: let both biases drift linearly
    over the recording (b(t) = b + b_dot (t - t_mid), b_dot per second) instead of constant. bias_walk:
    the biases as random walks (Kalibr's bias splines): each a cubic B-spline on the trajectory's knots
    whose consecutive controls differ by N(0, random_walk^2 knot_spacing_s) per axis (the noise file's
    random-walk densities); the reported biases are the walks' means. hold_td_s: hold td at this value
    instead of estimating it. folds: k of the k-fold held-out residuals (0: none). jackknife_blocks:
    contiguous time blocks of the delete-one-block jackknife that can widen the sigmas (under 3: none).
    max_iterations: per LM run. margin_s: the spline's reach beyond the first and last frame (td may
    move within it). imu_model: one of ``core.imu.intrinsics.IMU_MODELS``; ``scale-misalignment`` adds
    the IMU's scale, misalignment, gyro-to-accelerometer rotation and g-sensitivity with weak priors."""

    knot_spacing_s: float = 0.05
    corner_sigma_px: float = 0.5
    fix_corner_sigma: bool = False
    fix_imu_sigma: bool = False
    estimate_line_delay: bool = False
    hold_td_s: float | None = None
    folds: int = 3
    jackknife_blocks: int = 10
    max_iterations: int = 40
    margin_s: float = 0.1
    bias_drift: bool = False
    bias_walk: bool = False
    imu_model: str = "calibrated"
    board_scale: bool = False


@dataclass
class _Extrinsic:
    """One camera's own states: T_imu_cam as (R_ic, t_ic), td (s), line delay (s per row)."""

    R_ic: np.ndarray
    t_ic: np.ndarray
    td: float
    line_delay: float = 0.0


@dataclass
class _State:
    ctrl: np.ndarray  # (n, 6) [phi, p], or (n, 12) [phi, p, b_g, b_a] with ``bias_walk``
    cams: list[_Extrinsic]
    R_g: np.ndarray
    b_g: np.ndarray
    b_a: np.ndarray
    b_g_dot: np.ndarray = field(default_factory=lambda: np.zeros(3))
    b_a_dot: np.ndarray = field(default_factory=lambda: np.zeros(3))
    imu_x: np.ndarray = field(default_factory=lambda: np.zeros(len(intrinsics.NAMES)))
    board_scale: float = 1.0
    cache: dict = field(default_factory=dict, repr=False)


@dataclass(frozen=True)
class HeldOut:
    """k-fold held-out RMS: each fold's corners (every k-th frame) and IMU samples (every k-th) left out,
    the solution moved by one Gauss-Newton step from the full one (the refit, to first order), and the
    left-out data predicted by it. Lists have one entry per fold."""

    corner_rms_px: list[float]
    gyro_rms_rad_s: list[float]
    accel_rms_m_s2: list[float]


@dataclass(frozen=True)
class ImuCameraSolution:
    """The answer. Conventions in the module docstring of ``core.imu``."""

    T_imu_cam: np.ndarray
    td_s: float
    td_held: bool
    line_delay_s: float | None
    gyro_bias_rad_s: np.ndarray
    accel_bias_m_s2: np.ndarray
    gravity_w_m_s2: np.ndarray
    gyro_bias_drift_rad_s2: np.ndarray | None  # per second, about the recording's middle (bias_drift)
    accel_bias_drift_m_s3: np.ndarray | None
    covariance: np.ndarray  # over ``state_names``
    state_names: tuple[str, ...]
    covariance_7: np.ndarray  # (rot 3 rad, trans 3 m, td s); td row/column zero when held
    sigma_rotation_deg: np.ndarray
    sigma_translation_mm: np.ndarray
    sigma_td_ms: float
    td_crlb_ms: float
    sigma_line_delay_us: float | None
    corner_sigma_px: float
    corner_rms_px: float
    gyro_rms_rad_s: float
    accel_rms_m_s2: float
    imu_variance_factors: tuple[float, float]
    sigma_inflation: dict[str, float]  # jackknife sigma / white-noise sigma per state, at least 1
    held_out: HeldOut | None
    iterations: int
    converged: bool
    n_frames: int
    n_corners: int
    n_outliers: int  # corners over OUTLIER_SIGMAS robust sigmas after the first solve, left out
    n_imu: int
    knots: Knots
    cpu_s: float
    plain: PlainResult
    residuals: dict[str, np.ndarray] = field(repr=False)
    imu_intrinsics: intrinsics.ImuIntrinsics | None = None  # with imu_model scale-misalignment
    board_scale: float = 1.0  # estimated with SolveOptions.board_scale (its variance in ``covariance``)

    @property
    def T_cam_imu(self) -> np.ndarray:
        """Kalibr's camchain-imucam T_cam_imu (p_cam = T_cam_imu p_imu)."""
        return se3.invert(self.T_imu_cam)

    @property
    def timeshift_cam_imu_s(self) -> float:
        """Kalibr's timeshift_cam_imu: t_imu = t_cam + shift, the same number as td_s."""
        return self.td_s


def state_names(n_cameras: int) -> tuple[str, ...]:
    """Every shared state of a solve over ``n_cameras`` cameras: ``SHARED_NAMES`` (the first camera and
    the IMU's states), then each further camera's own eight as ``camK.NAME``."""
    own = SHARED_NAMES[:CAMERA_STATES]
    return SHARED_NAMES + tuple(f"cam{c}.{n}" for c in range(1, n_cameras) for n in own)


def _camera_columns(c: int) -> np.ndarray:
    """Columns of camera ``c``'s own states in ``state_names`` order."""
    first = 0 if c == 0 else len(SHARED_NAMES) + CAMERA_STATES * (c - 1)
    return first + np.arange(CAMERA_STATES)


class _Camera:
    """One camera's corners, fixed for a solve (times relative to ``t_ref``)."""

    def __init__(
        self, frames: CameraFrames, options: SolveOptions, t_ref: float, c: int, T_cam0_cam: np.ndarray | None
    ) -> None:
        self.K, self.dist = frames.camera_matrix, frames.dist_coeffs
        self.columns = _camera_columns(c)
        self.T_cam0_cam = (
            T_cam0_cam  # held: T_imu_cam = T_imu_cam0 T_cam0_cam (no extrinsic states of its own)
        )
        counts = np.array([p.shape[0] for p in frames.object_points])
        use = np.flatnonzero(counts >= 4)
        if use.size == 0:
            raise ImuInputError(f"camera {c} sees no board with 4 corners or more")
        self.frame_of_corner = np.repeat(use, counts[use])
        self.obj = np.concatenate([frames.object_points[f] for f in use])
        self.img = np.concatenate([frames.image_points[f] for f in use])
        self.t_cam = frames.t_s[self.frame_of_corner] - t_ref
        self.span = (frames.t_s[use[0]] - t_ref, frames.t_s[use[-1]] - t_ref)
        self.row = self.img[:, 1] - self.K[1, 2]
        if options.estimate_line_delay:
            self.pose_of_corner = np.arange(self.obj.shape[0])
        else:
            self.pose_of_corner = np.repeat(np.arange(use.size), counts[use])
        self.pose_starts = np.flatnonzero(np.r_[True, np.diff(self.pose_of_corner) != 0])
        self.sigma_px = options.corner_sigma_px
        self.corner_mask = np.ones(self.obj.shape[0])
        self.inliers = np.ones(self.obj.shape[0], bool)


class _Problem:
    """Data fixed for one solve (times relative to ``t_ref``): the cameras' corners and one IMU."""

    def __init__(
        self,
        imu: ImuSamples,
        cameras: Sequence[CameraFrames],
        noise: ImuNoise,
        options: SolveOptions,
        td0: Sequence[float],
        t_ref: float,
        rig: Sequence[np.ndarray | None],
    ) -> None:
        self.opt = options
        self.g_mag = noise.gravity_m_s2
        # Per-knot size of the banded states: the pose, and with ``bias_walk`` both biases' controls.
        self.k = 12 if options.bias_walk else 6
        self.walk_info = np.r_[
            np.full(3, 1.0 / (noise.gyro_random_walk**2 * options.knot_spacing_s)),
            np.full(3, 1.0 / (noise.accel_random_walk**2 * options.knot_spacing_s)),
        ]
        self.cams = [
            _Camera(f, options, t_ref, c, T) for c, (f, T) in enumerate(zip(cameras, rig, strict=True))
        ]
        t_first = min(cam.span[0] + td for cam, td in zip(self.cams, td0, strict=True))
        t_last = max(cam.span[1] + td for cam, td in zip(self.cams, td0, strict=True))
        self.knots = Knots.covering(t_first, t_last, options.knot_spacing_s, options.margin_s)
        t_imu = imu.t_s - t_ref
        keep = (t_imu >= self.knots.t0_s + options.knot_spacing_s) & (
            t_imu < self.knots.t_end_s - options.knot_spacing_s
        )
        self.t_imu = t_imu[keep]
        self.gyro = imu.gyro_rad_s[keep]
        self.accel = imu.accel_m_s2[keep]
        rate = imu.rate_hz
        self.sigma_gyro = noise.gyro_noise_density * np.sqrt(rate)
        self.sigma_accel = noise.accel_noise_density * np.sqrt(rate)
        seg, u = self.knots.locate(self.t_imu)
        self.imu_seg = seg
        self.imu_w = [self.knots.weights(u, d) for d in range(3)]
        self.imu_mask = np.ones(self.t_imu.size)
        self.names = state_names(len(self.cams))
        held = {int(i) for cam in self.cams if cam.T_cam0_cam is not None for i in cam.columns}
        self.width = len(self.names)
        self.active = [
            i
            for i, full in enumerate(self.names)
            if not ((name := full.split(".")[-1]) == "td" and options.hold_td_s is not None)
            and not (name == "line_delay" and not options.estimate_line_delay)
            and not (name.startswith(("dbg", "dba")) and not options.bias_drift)
            and not (name.startswith(("bg_", "ba_")) and options.bias_walk)
            and not (i in held and name in SHARED_NAMES[:6])
            and not (name in intrinsics.NAMES and options.imu_model == "calibrated")
            and not (name == "board_scale" and not options.board_scale)
        ]
        # The IMU model's weak priors: (position among the active states, index into imu_x, 1/sigma^2).
        inside = range(INTRINSICS.start, INTRINSICS.stop)
        prior = [(k, i - INTRINSICS.start) for k, i in enumerate(self.active) if i in inside]
        self.prior_at = np.array([k for k, _ in prior], int)
        self.prior_of = np.array([j for _, j in prior], int)
        self.prior_info = 1.0 / intrinsics.PRIOR_SIGMAS[self.prior_of] ** 2
        self.tau = self.t_imu - 0.5 * (self.t_imu[0] + self.t_imu[-1])
        self.R_ref = np.eye(3)

    # -- corners -------------------------------------------------------------------------------------
    def _pose_times(self, s: _State, c: int) -> tuple[np.ndarray, np.ndarray]:
        cam, e = self.cams[c], s.cams[c]
        first = cam.pose_starts
        t = cam.t_cam[first] + e.td
        row = cam.row[first]
        if self.opt.estimate_line_delay:
            t = t + e.line_delay * row
        return t, row

    def corners(self, s: _State, c: int, jacobians: bool):
        """Camera ``c``'s residuals (N, 2) px (observed - predicted), and per pose point: info (P, 6, 6),
        grad (P, 6), J_local (P, 6, 24), J_shared (P, 6, width), segment (P,)."""
        cam, e = self.cams[c], s.cams[c]
        t, row = self._pose_times(s, c)
        seg, u = self.knots.locate(t)
        w0 = self.knots.weights(u)
        loc = local_controls(s.ctrl, seg)[:, :, :6]
        R, tt = model.camera_pose(loc, w0, self.R_ref, e.R_ic, e.t_ic)
        pc = cam.pose_of_corner
        RX = np.einsum("nij,nj->ni", R[pc], cam.obj) * s.board_scale
        Xc = RX + tt[pc]
        pred = model.project(Xc, cam.K, cam.dist)
        r = cam.img - pred
        if not jacobians:
            return r
        # d pixel / d X_cam by central differences, then the pose chain (left rotation, translation).
        dX = np.empty((Xc.shape[0], 2, 3))
        for a in range(3):
            h = 1e-6 * np.maximum(np.abs(Xc[:, 2]), 1e-3)
            d = np.zeros(3)
            d[a] = 1.0
            dX[:, :, a] = (
                model.project(Xc + h[:, None] * d, cam.K, cam.dist)
                - model.project(Xc - h[:, None] * d, cam.K, cam.dist)
            ) / (2 * h[:, None])
        J_xi = np.concatenate([-np.einsum("nij,njk->nik", dX, _skew(RX)), dX], axis=2)  # (N, 2, 6)
        wgt = cam.corner_mask / cam.sigma_px**2
        info = np.add.reduceat(
            np.transpose(J_xi, (0, 2, 1)) @ (J_xi * wgt[:, None, None]), cam.pose_starts, axis=0
        )
        grad = np.add.reduceat(np.einsum("nri,nr,n->ni", J_xi, r, wgt), cam.pose_starts, axis=0)

        # d xi / d (local controls, extrinsic, time) per pose point.
        def xi(Rp: np.ndarray, tp: np.ndarray) -> np.ndarray:
            return np.concatenate(
                [se3.rotvecs_from_rotations(Rp @ np.transpose(R, (0, 2, 1))), tp - tt], axis=1
            )

        P, kk = t.size, self.k
        J_loc = np.zeros((P, 6, 4 * kk))
        for j in range(4):
            for k in range(3):
                d = np.zeros((4, 6))
                d[j, k] = H_CTRL
                plus = model.camera_pose(loc + d, w0, self.R_ref, e.R_ic, e.t_ic)
                minus = model.camera_pose(loc - d, w0, self.R_ref, e.R_ic, e.t_ic)
                J_loc[:, :, j * kk + k] = (xi(*plus) - xi(*minus)) / (2 * H_CTRL)
        # t_cam_w = R_ic^T (-R_i_w p - t_ic): linear in the position control points, rotation untouched.
        for j in range(4):
            J_loc[:, 3:, j * kk + 3 : j * kk + 6] = -R * w0[:, j, None, None]
        J_own = np.zeros((P, 6, CAMERA_STATES))
        for a in range(3):
            dv = np.zeros(3)
            dv[a] = H_CTRL
            Rp, Rm = se3.rotation_from_rotvec(dv) @ e.R_ic, se3.rotation_from_rotvec(-dv) @ e.R_ic
            J_own[:, :, a] = (
                xi(*model.camera_pose(loc, w0, self.R_ref, Rp, e.t_ic))
                - xi(*model.camera_pose(loc, w0, self.R_ref, Rm, e.t_ic))
            ) / (2 * H_CTRL)
            J_own[:, :, 3 + a] = (
                xi(*model.camera_pose(loc, w0, self.R_ref, e.R_ic, e.t_ic + dv))
                - xi(*model.camera_pose(loc, w0, self.R_ref, e.R_ic, e.t_ic - dv))
            ) / (2 * H_CTRL)
        shift = H_TIME / self.knots.dt_s
        plus = model.camera_pose(loc, self.knots.weights(u + shift), self.R_ref, e.R_ic, e.t_ic)
        minus = model.camera_pose(loc, self.knots.weights(u - shift), self.R_ref, e.R_ic, e.t_ic)
        dt_col = (xi(*plus) - xi(*minus)) / (2 * H_TIME)
        J_own[:, :, 6] = dt_col
        J_own[:, :, 7] = dt_col * row[:, None]
        J_sh = np.zeros((P, 6, self.width))
        if cam.T_cam0_cam is None:
            J_sh[:, :, cam.columns] = J_own
        else:
            # R = Exp(d) R_0 R_c0c, t = Exp(d) R_0 t_c0c + t_0: d moves t by -skew(R_0 t_c0c) d.
            first = self.cams[0].columns
            lever = _skew((s.cams[0].R_ic @ cam.T_cam0_cam[:3, 3])[None])[0]
            J_sh[:, :, first[0:3]] = J_own[:, :, 0:3] - J_own[:, :, 3:6] @ lever
            J_sh[:, :, first[3:6]] = J_own[:, :, 3:6]
            J_sh[:, :, cam.columns[6:]] = J_own[:, :, 6:]
        # A board scaled by k projects as the camera's translation scaled by 1/k (projection ignores depth
        # scale): d xi / d scale = (0, -t / scale).
        J_sh[:, 3:, BOARD_SCALE] = -tt / s.board_scale
        return r, info, grad, J_loc, J_sh, seg

    # -- IMU -----------------------------------------------------------------------------------------
    def gravity(self, R_g: np.ndarray) -> np.ndarray:
        return R_g @ np.array([0.0, 0.0, -self.g_mag])

    def imu(self, s: _State, jacobians: bool):
        """Residuals (S, 6) [gyro, accel] observed - predicted; J_local (S, 6, 24), J_shared (S, 6, width)."""
        loc = local_controls(s.ctrl, self.imu_seg)[:, :, :6]
        w0, w1, w2 = self.imu_w
        g_w = self.gravity(s.R_g)
        gy, ac = model.imu_predict(loc, w0, w1, w2, self.R_ref, g_w)
        # What the IMU measures of the true rate and specific force (identity for ``calibrated``).
        T = intrinsics.measurement_map(s.imu_x)
        raw = np.concatenate([gy, ac], axis=1)
        pred = raw @ T.T
        r = np.concatenate([self.gyro, self.accel], axis=1) - pred - self.bias(s)
        if not jacobians:
            return r
        S, kk = r.shape[0], self.k
        J_loc = np.zeros((S, 6, 4 * kk))
        for j in range(4):
            for c in range(3):
                d = np.zeros((4, 6))
                d[j, c] = H_CTRL
                gp, ap = model.imu_predict(loc + d, w0, w1, w2, self.R_ref, g_w)
                gm, am = model.imu_predict(loc - d, w0, w1, w2, self.R_ref, g_w)
                J_loc[:, :3, j * kk + c] = (gp - gm) / (2 * H_CTRL)
                J_loc[:, 3:, j * kk + c] = (ap - am) / (2 * H_CTRL)
        # accel = R_i_w (p'' - g): linear in the position control points.
        R_i_w = np.transpose(self.R_ref @ model.exp_so3(model.spline_value(loc[:, :, :3], w0)), (0, 2, 1))
        for j in range(4):
            J_loc[:, 3:, j * kk + 3 : j * kk + 6] = R_i_w * w2[:, j, None, None]
        J_sh = np.zeros((S, 6, self.width))
        for a in range(2):
            dv = np.zeros(3)
            dv[a] = H_GRAV
            _, ap = model.imu_predict(
                loc, w0, w1, w2, self.R_ref, self.gravity(s.R_g @ se3.rotation_from_rotvec(dv))
            )
            _, am = model.imu_predict(
                loc, w0, w1, w2, self.R_ref, self.gravity(s.R_g @ se3.rotation_from_rotvec(-dv))
            )
            J_sh[:, 3:, 8 + a] = (ap - am) / (2 * H_GRAV)
        if self.opt.imu_model != "calibrated":
            J_loc = np.einsum("ij,sjk->sik", T, J_loc)
            J_sh[:, :, 8:10] = np.einsum("ij,sjk->sik", T, J_sh[:, :, 8:10])
            J_sh[:, :, INTRINSICS] = np.einsum("kij,sj->sik", intrinsics.map_jacobians(s.imu_x), raw)
        if self.opt.bias_walk:  # the biases' controls enter after the IMU model, linearly
            for j in range(4):
                J_loc[:, :, j * kk + 6 : j * kk + 12] = np.eye(6) * w0[:, j, None, None]
        J_sh[:, :3, 10:13] = np.eye(3)
        J_sh[:, 3:, 13:16] = np.eye(3)
        J_sh[:, :3, 16:19] = np.eye(3) * self.tau[:, None, None]
        J_sh[:, 3:, 19:22] = np.eye(3) * self.tau[:, None, None]
        return r, J_loc, J_sh

    def bias(self, s: _State) -> np.ndarray:
        """(S, 6) [gyro, accel] bias at every IMU sample: the walks' splines (``bias_walk``), or the
        constants plus their linear drift."""
        if self.opt.bias_walk:
            return model.spline_value(local_controls(s.ctrl, self.imu_seg)[:, :, 6:], self.imu_w[0])
        tau = self.tau[:, None]
        return np.concatenate([s.b_g + s.b_g_dot * tau, s.b_a + s.b_a_dot * tau], axis=1)

    def imu_weights(self) -> np.ndarray:
        return np.r_[np.full(3, 1 / self.sigma_gyro), np.full(3, 1 / self.sigma_accel)]

    # -- normal equations ----------------------------------------------------------------------------
    def evaluate(self, s: _State) -> DenseSystem:
        act = self.active
        parts = [self.corners(s, c, True) for c in range(len(self.cams))]
        info, grad, Jl_c, Js_c, seg_c = (np.concatenate([q[k] for q in parts]) for k in range(1, 6))
        Js_c = Js_c[:, :, act]
        r_i, Jl_i, Js_i = self.imu(s, True)
        Js_i = Js_i[:, :, act]
        wv = self.imu_weights()[None, :] * self.imu_mask[:, None]
        r_iw = r_i * wv
        Jl_i = Jl_i * wv[:, :, None]
        Js_i = Js_i * wv[:, :, None]
        cost = float(
            sum(
                np.sum(q[0] ** 2 * (cam.corner_mask / cam.sigma_px**2)[:, None])
                for q, cam in zip(parts, self.cams, strict=True)
            )
            + np.sum(r_iw**2)
        )
        n = self.knots.n
        order = np.argsort(seg_c, kind="stable")  # line-delay pose points need not be in time order
        Jl_c, info, grad, Js_c, seg_c = Jl_c[order], info[order], grad[order], Js_c[order], seg_c[order]
        JlT_info = np.transpose(Jl_c, (0, 2, 1)) @ info
        band_c, cross_c, gl_c = scatter_band(
            n, seg_c, JlT_info @ Jl_c, JlT_info @ Js_c, np.einsum("pia,pi->pa", Jl_c, grad)
        )
        # One Gram matrix per segment over [local | shared | residual] columns: the IMU's blocks of the
        # band, the cross terms, both gradients and its share of A at once.
        q = Jl_i.shape[2]
        seg_i, G = segment_gram(self.imu_seg, np.concatenate([Jl_i, Js_i, r_iw[:, :, None]], axis=2))
        band_i, cross_i, gl_i = scatter_band(n, seg_i, G[:, :q, :q], G[:, :q, q:-1], G[:, :q, -1])
        band = band_c + band_i
        floor = BAND_FLOOR * max(float(np.max(np.diagonal(band[:, 0], axis1=1, axis2=2))), 1.0)
        band[:, 0] += floor * np.eye(self.k)
        cross = cross_c + cross_i
        g_l = gl_c + gl_i
        if self.opt.bias_walk:
            cost += self._walk_prior(s.ctrl[:, 6:], band, g_l)
        A = np.einsum("pia,pij,pjb->ab", Js_c, info, Js_c) + G[:, q:-1, q:-1].sum(axis=0)
        g_s = np.einsum("pia,pi->a", Js_c, grad) + G[:, q:-1, -1].sum(axis=0)
        chol = BandedCholesky(band)
        X = chol.solve(np.concatenate([cross, g_l[:, :, None]], axis=2))
        X_B, X_g = X[:, :, :-1], X[:, :, -1]
        S = A - np.einsum("nkp,nkq->pq", cross, X_B)
        g = g_s - np.einsum("nkp,nk->p", cross, X_g)
        if self.prior_at.size:  # the IMU model's priors at zero: residual -x, Jacobian I
            x = s.imu_x[self.prior_of]
            S[self.prior_at, self.prior_at] += self.prior_info
            g[self.prior_at] -= self.prior_info * x
            cost += float(np.sum(self.prior_info * x**2))
        s.cache = {"X_B": X_B, "X_g": X_g, "A": A}
        return DenseSystem(cost, 0.5 * (S + S.T), g)

    def _walk_prior(self, bias: np.ndarray, band: np.ndarray, g_l: np.ndarray) -> float:
        """The biases as random walks: consecutive controls differ by the walk's increment over one knot
        spacing, N(0, random_walk^2 dt) per axis (Kalibr's bias motion term), added into the band and
        the spline's gradient in place; returns its cost."""
        step = np.diff(bias, axis=0)  # (n - 1, 6)
        W = np.diag(self.walk_info)
        band[:-1, 0, 6:, 6:] += W
        band[1:, 0, 6:, 6:] += W
        band[:-1, 1, 6:, 6:] -= W
        g_l[:-1, 6:] += self.walk_info * step
        g_l[1:, 6:] -= self.walk_info * step
        return float(np.sum(self.walk_info * step**2))

    def retract(self, s: _State, delta: np.ndarray) -> _State:
        full = np.zeros(self.width)
        full[self.active] = delta
        d_ctrl = s.cache["X_g"] - np.einsum("nkp,p->nk", s.cache["X_B"], delta)
        cams = []
        for cam, e in zip(self.cams, s.cams, strict=True):
            d = full[cam.columns]
            cams.append(
                _Extrinsic(
                    se3.rotation_from_rotvec(d[0:3]) @ e.R_ic,
                    e.t_ic + d[3:6],
                    e.td + d[6],
                    e.line_delay + d[7],
                )
            )
        return _State(
            ctrl=s.ctrl + d_ctrl,
            cams=self.tie(cams),
            R_g=s.R_g @ se3.rotation_from_rotvec(np.r_[full[8:10], 0.0]),
            b_g=s.b_g + full[10:13],
            b_a=s.b_a + full[13:16],
            b_g_dot=s.b_g_dot + full[16:19],
            b_a_dot=s.b_a_dot + full[19:22],
            imu_x=s.imu_x + full[INTRINSICS],
            board_scale=s.board_scale + full[BOARD_SCALE],
        )

    def tie(self, cams: list[_Extrinsic]) -> list[_Extrinsic]:
        """Each held camera's extrinsic from the first camera's through its rig pose."""
        R_0, t_0 = cams[0].R_ic, cams[0].t_ic
        for cam, e in zip(self.cams, cams, strict=True):
            if cam.T_cam0_cam is not None:
                e.R_ic, e.t_ic = R_0 @ cam.T_cam0_cam[:3, :3], R_0 @ cam.T_cam0_cam[:3, 3] + t_0
        return cams

    def solve(self, s: _State, max_iterations: int) -> tuple[_State, DenseSystem, int, bool]:
        result = solve_lm(
            self.evaluate,
            s,
            self.retract,
            damping=Damping(initial=1e-4),
            max_iterations=max_iterations,
            relative_tolerance=1e-7,
            label="the camera-IMU solve",
            hint="check the IMU units, the held intrinsics and that the recording moves the board in view",
        )
        system = self.evaluate(result.params)
        return result.params, system, result.iterations, result.converged


def _skew(v: np.ndarray) -> np.ndarray:
    K = np.zeros((v.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return K


def _initial_state(
    problem: _Problem,
    tracks: Sequence[BoardTrack],
    plains: Sequence[PlainResult],
    t_ref: float,
    td0: Sequence[float],
) -> _State:
    """The spline fitted to the first camera's PnP poses carried into the IMU by its plain extrinsic
    (linear least squares on knot-centre samples, poses interpolated between frames); every camera's
    extrinsic and td from its own plain result, the biases and gravity from the first camera's."""
    track, plain, td = tracks[0], plains[0], td0[0]
    T_c_i = se3.invert(plain.T_imu_cam)
    T_w_i = track.T_w_cam @ T_c_i
    t_pose = track.t_s - t_ref + td
    R_w_i = T_w_i[:, :3, :3]
    mid = R_w_i[R_w_i.shape[0] // 2]
    problem.R_ref = mid
    phi = se3.rotvecs_from_rotations(np.einsum("ji,njk->nik", mid, R_w_i))
    turn = float(np.max(np.linalg.norm(phi, axis=1)))
    if turn > MAX_TURN_RAD:
        raise ImuInputError(
            f"the recording turns {np.degrees(turn):.0f} deg away from its middle pose; the trajectory "
            f"model holds {np.degrees(MAX_TURN_RAD):.0f} deg: cut the recording to the part that faces the "
            "board"
        )
    knots = problem.knots
    t_s = knots.t0_s + (np.arange(4 * knots.n) / 4) * knots.dt_s
    t_s = t_s[t_s < knots.t_end_s]
    tc = np.clip(t_s, t_pose[0], t_pose[-1])
    vals = np.stack(
        [np.interp(tc, t_pose, phi[:, k]) for k in range(3)]
        + [np.interp(tc, t_pose, T_w_i[:, k, 3]) for k in range(3)],
        axis=1,
    )
    seg, u = knots.locate(t_s)
    w = knots.weights(u)
    J = np.einsum("mj,cd->mcjd", w, np.eye(6)).reshape(-1, 6, 24)
    band, cross, g = scatter_band(
        knots.n,
        seg,
        np.einsum("mra,mrb->mab", J, J),
        np.zeros((seg.size, 24, 1)),
        np.einsum("mra,mr->ma", J, vals),
    )
    band[:, 0] += 1e-9 * np.eye(6)
    ctrl = BandedCholesky(band).solve(g[:, :, None])[:, :, 0]
    if problem.k == 12:  # bias_walk: every bias control at the plain start's constant
        biases = np.r_[plain.gyro_bias_rad_s, plain.accel_bias_m_s2]
        ctrl = np.concatenate([ctrl, np.tile(biases, (knots.n, 1))], axis=1)
    gravity = plain.gravity_w_m_s2 / np.linalg.norm(plain.gravity_w_m_s2)
    # R_g maps [0, 0, -1] onto the measured gravity direction.
    axis = np.cross([0.0, 0.0, -1.0], gravity)
    angle = np.arctan2(np.linalg.norm(axis), np.dot([0.0, 0.0, -1.0], gravity))
    R_g = se3.rotation_from_rotvec(axis / max(np.linalg.norm(axis), 1e-12) * angle)
    return _State(
        ctrl,
        problem.tie(
            [
                _Extrinsic(q.T_imu_cam[:3, :3].copy(), q.T_imu_cam[:3, 3].copy(), t)
                for q, t in zip(plains, td0, strict=True)
            ]
        ),
        R_g,
        plain.gyro_bias_rad_s.copy(),
        plain.accel_bias_m_s2.copy(),
    )


def _safe_inverse(S: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric PSD matrix through its scaled eigen-decomposition; a direction the data
    cannot see gets a very large variance (eigenvalues floored at 1e-14 of the largest), not a crash."""
    d = np.sqrt(np.maximum(np.diag(S), 1e-300))
    Sn = S / np.outer(d, d)
    vals, vecs = np.linalg.eigh(Sn)
    vals = np.maximum(vals, 1e-14 * max(vals.max(), 1e-300))
    return (vecs / vals) @ vecs.T / np.outer(d, d)


def solve_imu_camera(
    imu: ImuSamples,
    frames: CameraFrames,
    noise: ImuNoise,
    options: SolveOptions = SolveOptions(),
    track: BoardTrack | None = None,
    plain: PlainResult | None = None,
) -> ImuCameraSolution:
    """Joint camera-IMU calibration of one camera (module docstring; ``solve_imu_cameras`` for several).

    Raises:
        ImuInputError / ImuUnitError: the recording cannot be aligned or is in the wrong units.
        NumericalError: the residuals are not finite at the start.
    """
    return solve_imu_cameras(
        imu,
        [frames],
        noise,
        options,
        None if track is None else [track],
        None if plain is None else [plain],
    )[0]


def solve_imu_cameras(
    imu: ImuSamples,
    cameras: Sequence[CameraFrames],
    noise: ImuNoise,
    options: SolveOptions = SolveOptions(),
    tracks: Sequence[BoardTrack] | None = None,
    plains: Sequence[PlainResult] | None = None,
    rig: Sequence[np.ndarray | None] | None = None,
) -> list[ImuCameraSolution]:
    """Several cameras and one IMU in one solve: each camera's own T_imu_cam, td (and line delay)
    against ONE IMU trajectory, gravity and biases, so every camera's corners pin the motion that the
    others' extrinsics are measured against. One solution per camera, in order; each carries its own
    states and the shared IMU states (covariance over ``state_names`` of a one-camera solve), its
    corners' residuals and the shared IMU residuals (``cpu_s`` and ``iterations`` are the whole joint
    solve's). The first camera's poses start the trajectory.

    ``rig``: per camera, its pose in the first camera's frame T_cam0_cam (4, 4) where the rig already
    relates the two (held: that camera's T_imu_cam = T_imu_cam0 T_cam0_cam, its corners then pin the
    first camera's extrinsic; its td stays its own), or None (estimated). The first entry is None.

    Raises:
        ImuInputError / ImuUnitError: the recording cannot be aligned or is in the wrong units.
        NumericalError: the residuals are not finite at the start.
    """
    cpu0 = time.process_time()
    if options.bias_walk and options.bias_drift:
        raise ValueError("bias_walk and bias_drift: choose one model of the biases' change")
    if options.imu_model not in intrinsics.IMU_MODELS:
        raise ValueError(f"imu_model: one of {', '.join(intrinsics.IMU_MODELS)}, not {options.imu_model!r}")
    if not cameras:
        raise ImuInputError("no camera to solve: give at least one camera's frames")
    rig = list(rig) if rig is not None else [None] * len(cameras)
    if len(rig) != len(cameras) or rig[0] is not None:
        raise ValueError("rig: one entry per camera, the first None (the cameras are posed in its frame)")
    tracks = list(tracks) if tracks is not None else [board_track(f) for f in cameras]
    plains = (
        list(plains)
        if plains is not None
        else [
            plain_calibration(imu, f, t, td_s=options.hold_td_s) for f, t in zip(cameras, tracks, strict=True)
        ]
    )
    td0 = [q.td_s if options.hold_td_s is None else options.hold_td_s for q in plains]
    t_ref = float(imu.t_s[0])
    problem = _Problem(imu, cameras, noise, options, td0, t_ref, rig)
    if problem.t_imu.size < 100:
        raise ImuInputError(
            "camera and IMU overlap for fewer than 100 IMU samples; do the logs share a clock?"
        )
    state = _initial_state(problem, tracks, plains, t_ref, td0)
    state, system, iterations, converged = problem.solve(state, options.max_iterations)
    # Variance components: each camera's corners from their RMS, IMU groups raised to theirs.
    for c, cam in enumerate(problem.cams):
        r_c = problem.corners(state, c, False)
        norm = np.linalg.norm(r_c, axis=1)
        robust_sigma = float(np.median(norm)) / np.sqrt(
            2 * np.log(2)
        )  # 2-D Gaussian: median |r| = 1.177 sigma
        cam.inliers = norm <= OUTLIER_SIGMAS * robust_sigma
        cam.corner_mask = cam.inliers.astype(float)
        if not options.fix_corner_sigma:
            cam.sigma_px = float(np.sqrt(np.mean(r_c[cam.inliers] ** 2)))
    r_i = problem.imu(state, False)
    f_g = max(1.0, float(np.sqrt(np.mean(r_i[:, :3] ** 2))) / problem.sigma_gyro)
    f_a = max(1.0, float(np.sqrt(np.mean(r_i[:, 3:] ** 2))) / problem.sigma_accel)
    if options.fix_imu_sigma:
        f_g = f_a = 1.0
    problem.sigma_gyro *= f_g
    problem.sigma_accel *= f_a
    state, system, more, converged = problem.solve(state, options.max_iterations)
    iterations += more
    bias = problem.bias(state)
    if options.bias_walk:  # each walk's mean over the recording is the bias reported
        state.b_g, state.b_a = bias[:, :3].mean(axis=0), bias[:, 3:].mean(axis=0)
    cov = _safe_inverse(system.H)
    A = state.cache["A"]
    at_imu = [k for k, i in enumerate(problem.active) if INTRINSICS.start <= i < INTRINSICS.stop]
    min_information = intrinsics.observability(cov[np.ix_(at_imu, at_imu)]) if at_imu else float("nan")
    inflation = np.ones(cov.shape[0])
    if options.jackknife_blocks >= 3:
        jk = _block_jackknife(problem, state, options.jackknife_blocks)
        ratio = np.diag(jk) / np.diag(cov)
        inflation = np.where(ratio > JACKKNIFE_RATIO, np.sqrt(ratio), 1.0)
        cov = cov * np.outer(inflation, inflation)
    held_out = _k_fold(problem, state, options) if options.folds >= 2 else None
    r_i = problem.imu(state, False)
    g_w = problem.gravity(state.R_g)
    index = {problem.names[i]: k for k, i in enumerate(problem.active)}
    imu_intrinsics = (
        intrinsics.ImuIntrinsics(
            options.imu_model, state.imu_x.copy(), np.sqrt(np.diag(cov)[at_imu]), min_information
        )
        if at_imu
        else None
    )
    cpu_s = time.process_time() - cpu0
    solutions = []
    for c, cam in enumerate(problem.cams):
        # This camera's states and the IMU's, under the names of a one-camera solve; a camera the rig
        # holds has the first camera's extrinsic states carried through its rig pose.
        T_rig = cam.T_cam0_cam
        held = T_rig is not None
        rows, names = [], []
        for name in SHARED_NAMES:
            owner = 0 if held and name in SHARED_NAMES[:6] else c
            full = name if owner == 0 or name not in SHARED_NAMES[:CAMERA_STATES] else f"cam{owner}.{name}"
            if full in index:
                rows.append(index[full])
                names.append(name)
        L = np.zeros((len(rows), cov.shape[0]))
        L[np.arange(len(rows)), rows] = 1.0
        if T_rig is not None:
            L[3:6, rows[0:3]] = -_skew((state.cams[0].R_ic @ T_rig[:3, 3])[None])[0]
        sub = L @ cov @ L.T
        own = {name: k for k, name in enumerate(names)}
        seven = np.zeros((7, 7))
        seven_names = ("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "td")
        have = [k for k, n in enumerate(seven_names) if n in own]
        at = [own[seven_names[k]] for k in have]
        seven[np.ix_(have, have)] = sub[np.ix_(at, at)]
        td_full = "td" if c == 0 else f"cam{c}.td"
        td_crlb = 1.0 / np.sqrt(A[index[td_full], index[td_full]]) if td_full in index else float("nan")
        e = state.cams[c]
        r_c = problem.corners(state, c, False)
        solutions.append(
            ImuCameraSolution(
                T_imu_cam=se3.transform(e.R_ic, e.t_ic),
                td_s=float(e.td),
                td_held=options.hold_td_s is not None,
                line_delay_s=float(e.line_delay) if options.estimate_line_delay else None,
                gyro_bias_rad_s=state.b_g,
                accel_bias_m_s2=state.b_a,
                gravity_w_m_s2=g_w,
                gyro_bias_drift_rad_s2=state.b_g_dot if options.bias_drift else None,
                accel_bias_drift_m_s3=state.b_a_dot if options.bias_drift else None,
                covariance=sub,
                state_names=tuple(names),
                covariance_7=seven,
                sigma_rotation_deg=np.degrees(np.sqrt(np.diag(seven)[:3])),
                sigma_translation_mm=1e3 * np.sqrt(np.diag(seven)[3:6]),
                sigma_td_ms=1e3 * float(np.sqrt(seven[6, 6])),
                td_crlb_ms=1e3 * float(td_crlb),
                sigma_line_delay_us=(
                    1e6 * float(np.sqrt(sub[own["line_delay"], own["line_delay"]]))
                    if "line_delay" in own
                    else None
                ),
                corner_sigma_px=cam.sigma_px,
                corner_rms_px=float(np.sqrt(np.mean(np.sum(r_c[cam.inliers] ** 2, axis=1)))),
                n_outliers=int(np.sum(~cam.inliers)),
                gyro_rms_rad_s=float(np.sqrt(np.mean(np.sum(r_i[:, :3] ** 2, axis=1)))),
                accel_rms_m_s2=float(np.sqrt(np.mean(np.sum(r_i[:, 3:] ** 2, axis=1)))),
                imu_variance_factors=(f_g, f_a),
                sigma_inflation=dict(zip(names, (float(inflation[k]) for k in rows), strict=True)),
                held_out=None if held_out is None else held_out[c],
                iterations=iterations,
                converged=converged,
                n_frames=int(np.unique(cam.frame_of_corner).size),
                n_corners=int(cam.obj.shape[0]),
                n_imu=int(problem.t_imu.size),
                knots=problem.knots,
                cpu_s=cpu_s,
                plain=plains[c],
                residuals={
                    "corner_px": r_c,
                    "corner_t_s": cam.t_cam + t_ref,
                    "corner_row_px": cam.row,
                    "corner_inlier": cam.inliers,
                    "imu_t_s": problem.t_imu + t_ref,
                    "gyro_rad_s": r_i[:, :3],
                    "accel_m_s2": r_i[:, 3:],
                    "gyro_bias_rad_s": bias[:, :3],
                    "accel_bias_m_s2": bias[:, 3:],
                },
                imu_intrinsics=imu_intrinsics,
                board_scale=float(state.board_scale),
            )
        )
    return solutions


def _one_step(
    problem: _Problem, state: _State, corners_out: Sequence[np.ndarray], imu_out: np.ndarray
) -> tuple[np.ndarray, _State]:
    """The solution with some corners (a mask per camera) and IMU samples left out, one Gauss-Newton
    step from ``state`` (the full solution): (shared delta, moved state). Restores the problem's masks."""
    for cam, out in zip(problem.cams, corners_out, strict=True):
        cam.corner_mask = (cam.inliers & ~out).astype(float)
    problem.imu_mask = (~imu_out).astype(float)
    probe = replace(state, cache={})
    system = problem.evaluate(probe)
    delta = np.linalg.lstsq(system.H, system.g, rcond=None)[0]
    for cam in problem.cams:
        cam.corner_mask = cam.inliers.astype(float)
    problem.imu_mask = np.ones(problem.t_imu.size)
    return delta, problem.retract(probe, delta)


def _block_jackknife(problem: _Problem, state: _State, blocks: int) -> np.ndarray:
    """Delete-one-block jackknife covariance over the active shared states (p, p).

    The camera span is cut into ``blocks`` contiguous time blocks; each block's corners (of every
    camera) and IMU samples are left out in turn and the solution moved by one Gauss-Newton step from
    the full one (the linearised jackknife: a block is a small share of the data). The spread of those
    K answers, (K - 1)/K sum (d_k - mean)(d_k - mean)^T, sees what the white-noise covariance cannot:
    residuals correlated in time (vibration, a lens error that follows the board across the image).
    """
    t_c = [cam.t_cam + e.td for cam, e in zip(problem.cams, state.cams, strict=True)]
    t_i = problem.t_imu
    edges = np.linspace(min(t.min() for t in t_c), max(t.max() for t in t_c), blocks + 1)
    edges[-1] += 1.0
    steps = []
    for b in range(blocks):
        inside_c = [(t >= edges[b]) & (t < edges[b + 1]) for t in t_c]
        inside_i = (t_i >= edges[b]) & (t_i < edges[b + 1])
        steps.append(_one_step(problem, state, inside_c, inside_i)[0])
    d = np.array(steps)
    d -= d.mean(axis=0)
    return (blocks - 1) / blocks * d.T @ d


def _k_fold(problem: _Problem, state: _State, options: SolveOptions) -> list[HeldOut]:
    """One ``HeldOut`` per camera: each fold leaves out every k-th frame of every camera and every k-th
    IMU sample (the IMU's lists are the same for every camera)."""
    k = options.folds
    frame_rank = [np.unique(cam.frame_of_corner, return_inverse=True)[1] for cam in problem.cams]
    sample = np.arange(problem.t_imu.size)
    outs = [HeldOut([], [], []) for _ in problem.cams]
    for f in range(k):
        out_c = [rank % k == f for rank in frame_rank]
        out_i = sample % k == f
        _, fold_state = _one_step(problem, state, out_c, out_i)
        r_i = problem.imu(fold_state, False)[out_i]
        gyro = float(np.sqrt(np.mean(np.sum(r_i[:, :3] ** 2, axis=1))))
        accel = float(np.sqrt(np.mean(np.sum(r_i[:, 3:] ** 2, axis=1))))
        for c, (cam, out) in enumerate(zip(problem.cams, outs, strict=True)):
            r_c = problem.corners(fold_state, c, False)[out_c[c] & cam.inliers]
            out.corner_rms_px.append(float(np.sqrt(np.mean(np.sum(r_c**2, axis=1)))))
            out.gyro_rms_rad_s.append(gyro)
            out.accel_rms_m_s2.append(accel)
    return outs
