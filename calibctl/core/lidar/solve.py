"""T_lidar_cam from boards seen by both sensors: closed form, joint least squares, covariance, held-out.

Closed form: the board plane is n_c . p = d_c in the camera and n_l . p = d_l in the LiDAR; with
p_lidar = R p_cam + t, n_l = R n_c and d_l = d_c + n_l . t. R is the Kabsch rotation of the camera
normals onto the LiDAR normals (SVD), t the least-squares solution of the stacked n_l . t = d_l - d_c
(plus the board centres, down-weighted, so three nearly parallel boards still give a start).

Joint least squares over all poses: unknowns T_lidar_cam (left perturbation: rotation about LiDAR
axes, translation in the LiDAR frame), every T_cam_board (nuisance, with the image's own pose
covariance as a prior: that is how the camera's uncertainty reaches the answer) and optionally a
LiDAR range offset. Residuals: each board point's distance to the camera-seen plane (point-to-plane),
and each ring end point's distance to the backing board's outline (edges; they fix the in-plane
directions the normals leave weak). Points of one ring run share a laser's range bias, so they are
not independent: a run of m points is whitened with C = s_w^2 I + s_b^2 11^T (s_w, s_b from the
residuals), which keeps 700 points per board from claiming 700 independent measurements.
Covariance: s^2 (J^T J)^-1 marginalised to T_lidar_cam (6x6; 7x7 with the range offset).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from calibctl.core.blas_threads import single_threaded_blas
from calibctl.core.extrinsics import se3
from calibctl.core.lidar.segment import BoardInScan
from calibctl.core.lidar.target import BackingBoard, CameraBoard, perturb, plane_in_camera
from calibctl.core.lm import Damping, DenseSystem, solve_lm
from calibctl.errors import NumericalError

MAX_ITERATIONS = 30
STEP_TOL = 1e-10  # stop when a step lowers the cost by less than this share of it
DAMPING = Damping(initial=1e-3, decrease=10.0, increase=10.0, floor=1e-9, ceiling=1e8)
EDGE_SIGMA_START_M = 0.01
CENTRE_WEIGHT = 0.2  # centres in the closed form: a weak pull, the planes lead


@dataclass(frozen=True)
class Pose:
    """One accepted pose: label, the camera's board and the LiDAR's board."""

    label: str
    camera: CameraBoard
    lidar: BoardInScan


@dataclass(frozen=True)
class NoiseModel:
    """LiDAR noise, metres: white per point, shared per ring run (laser bias), edge position."""

    white_m: float
    run_bias_m: float
    edge_m: float


@dataclass(frozen=True)
class LidarSolution:
    """T_lidar_cam (4, 4), its 6x6 covariance over (rot about LiDAR x y z rad, translation m), the
    range offset (m, 0 unless estimated) and its sigma, residual RMS values in metres."""

    T_lidar_cam: np.ndarray
    covariance: np.ndarray
    range_offset_m: float
    range_offset_sigma_m: float | None
    plane_rms_m: float
    edge_rms_m: float
    per_pose_plane_rms_m: tuple[float, ...]
    noise: NoiseModel
    iterations: int
    pose_offset_sigma_m: float = 0.0
    laser_bias_m: np.ndarray | None = None  # (lasers,) range correction per ring index, m
    pose_tilt_sigma_rad: float = 0.0

    @property
    def sigma_rotation_deg(self) -> np.ndarray:
        return np.degrees(np.sqrt(np.diag(self.covariance)[:3]))

    @property
    def sigma_translation_m(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance)[3:6])


def closed_form(poses: Sequence[Pose], board: BackingBoard) -> np.ndarray:
    """(4, 4) T_lidar_cam from plane normals and distances (module docstring)."""
    nc = np.array([plane_in_camera(p.camera.T_cam_board)[0] for p in poses])
    dc = np.array([plane_in_camera(p.camera.T_cam_board)[1] for p in poses])
    nl = np.array([p.lidar.normal for p in poses])
    dl = np.array([p.lidar.distance_m for p in poses])
    U, _, Vt = np.linalg.svd(nc.T @ nl)
    D = np.diag([1.0, 1.0, np.linalg.det(Vt.T @ U.T)])
    R = Vt.T @ D @ U.T
    centre_pattern = np.append(board.centre_in_pattern(), 1.0)
    cc = np.array([(p.camera.T_cam_board @ centre_pattern)[:3] for p in poses])
    cl = np.array([p.lidar.centre_m for p in poses])
    A = np.vstack([nl, CENTRE_WEIGHT * np.tile(np.eye(3), (len(poses), 1))])
    b = np.concatenate([dl - dc, CENTRE_WEIGHT * (cl - cc @ R.T).reshape(-1)])
    t = np.linalg.lstsq(A, b, rcond=None)[0]
    return se3.transform(R, t)


def _runs_of(pose: Pose) -> list[np.ndarray]:
    ring = pose.lidar.ring_of_point
    return [np.flatnonzero(ring == r) for r in np.unique(ring)]


def _whiten(resid: np.ndarray, runs: list[np.ndarray], noise: NoiseModel) -> np.ndarray:
    out = np.empty_like(resid)
    for idx in runs:
        m = len(idx)
        c = 1.0 - noise.white_m / np.sqrt(noise.white_m**2 + m * noise.run_bias_m**2)
        r = resid[idx]
        out[idx] = (r - c * r.mean()) / noise.white_m
    return out


def _corrected(points_m: np.ndarray, correction_m: np.ndarray | float) -> np.ndarray:
    """Points moved along their rays by ``correction_m`` (scalar or (N,)), metres."""
    if np.isscalar(correction_m) and correction_m == 0.0:
        return points_m
    unit = points_m / np.linalg.norm(points_m, axis=1, keepdims=True)
    return points_m + np.reshape(correction_m, (-1, 1)) * unit


def pose_residuals(
    T_lidar_cam: np.ndarray,
    T_cam_board: np.ndarray,
    pose: Pose,
    board: BackingBoard,
    range_correction_m: float = 0.0,
    laser_bias_m: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Raw residuals of one pose, metres: ((M,) board points to the camera's plane, (E,) edge points to
    the backing board's outline, both in the pattern frame). ``laser_bias_m``: a correction per ring index."""
    T_board_lidar = se3.invert(T_lidar_cam @ T_cam_board)
    corr_p: np.ndarray | float = range_correction_m
    corr_e: np.ndarray | float = range_correction_m
    if laser_bias_m is not None:
        corr_p = range_correction_m + laser_bias_m[pose.lidar.ring_of_point]
        corr_e = range_correction_m + laser_bias_m[pose.lidar.edge_ring]
    pts = _corrected(pose.lidar.points_m, corr_p) @ T_board_lidar[:3, :3].T + T_board_lidar[:3, 3]
    edges = _corrected(pose.lidar.edge_points_m, corr_e) @ T_board_lidar[:3, :3].T + T_board_lidar[:3, 3]
    rel = np.abs(edges[:, :2] - board.centre_in_pattern()[:2])
    half = np.array(board.backing_m) / 2
    gaps = rel - half  # signed distance to the side each coordinate points at
    nearest = np.argmin(np.abs(gaps), axis=1)
    return pts[:, 2], gaps[np.arange(len(gaps)), nearest]


def range_derivatives(
    T_lidar_cam: np.ndarray,
    T_cam_board: np.ndarray,
    pose: Pose,
    board: BackingBoard,
    range_correction_m: float = 0.0,
    laser_bias_m: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """d(residual)/d(range correction) of each board point (M,) and edge point (E,): the ray direction in
    the pattern frame (z for the plane, the nearest side's axis for an edge). Residuals are linear in a
    range correction along a fixed ray, so this is exact, and spares the solve a finite difference per
    laser."""
    T_board_lidar = se3.invert(T_lidar_cam @ T_cam_board)
    Rb = T_board_lidar[:3, :3]
    unit_p = pose.lidar.points_m / np.linalg.norm(pose.lidar.points_m, axis=1, keepdims=True)
    unit_e = pose.lidar.edge_points_m / np.linalg.norm(pose.lidar.edge_points_m, axis=1, keepdims=True)
    corr_e: np.ndarray | float = range_correction_m
    if laser_bias_m is not None:
        corr_e = range_correction_m + laser_bias_m[pose.lidar.edge_ring]
    edges = _corrected(pose.lidar.edge_points_m, corr_e) @ Rb.T + T_board_lidar[:3, 3]
    signed = edges[:, :2] - board.centre_in_pattern()[:2]
    nearest = np.argmin(np.abs(np.abs(signed) - np.array(board.backing_m) / 2), axis=1)
    rows = np.arange(len(edges))
    de = (unit_e @ Rb.T)[:, :2][rows, nearest] * np.sign(signed[rows, nearest])
    return (unit_p @ Rb.T)[:, 2], de


@dataclass(frozen=True)
class _Layout:
    """Where the global unknowns sit: 6 for T_lidar_cam, one bias per laser, then the range offset."""

    lasers: int
    with_offset: bool

    @property
    def size(self) -> int:
        return 6 + self.lasers + int(self.with_offset)

    def split(self, xg: np.ndarray) -> tuple[np.ndarray, float]:
        return xg[6 : 6 + self.lasers], float(xg[-1]) if self.with_offset else 0.0


def _whitened(
    xg: np.ndarray,
    layout: _Layout,
    T0: np.ndarray,
    pose: Pose,
    board: BackingBoard,
    local: np.ndarray,
    noise: NoiseModel,
    prior_sqrt: np.ndarray,
    runs: list[np.ndarray],
) -> np.ndarray:
    T = perturb(T0, xg[:6])
    T_cb = perturb(pose.camera.T_cam_board, local)
    biases, offset = layout.split(xg)
    plane, edge = pose_residuals(T, T_cb, pose, board, offset, biases)
    return np.concatenate([_whiten(plane, runs, noise), edge / noise.edge_m, prior_sqrt @ local])


def estimate_noise(poses: Sequence[Pose], plane_resid: Sequence[np.ndarray], edge_m: float) -> NoiseModel:
    """White and run-shared parts of the point-to-plane residuals (variance components), metres."""
    within, between, sizes = [], [], []
    for pose, r in zip(poses, plane_resid, strict=True):
        r = r - r.mean()
        for idx in _runs_of(pose):
            if len(idx) >= 2:
                within.append(np.sum((r[idx] - r[idx].mean()) ** 2) / (len(idx) - 1))
                between.append(r[idx].mean())
                sizes.append(len(idx))
    white = float(np.sqrt(np.mean(within))) if within else 0.01
    bias2 = float(np.var(between) - white**2 / np.mean(sizes)) if between else 0.0
    return NoiseModel(max(white, 1e-4), float(np.sqrt(max(bias2, (0.1 * white) ** 2))), max(edge_m, 1e-4))


def joint_solve(
    poses: Sequence[Pose],
    board: BackingBoard,
    T_start: np.ndarray,
    noise: NoiseModel,
    estimate_range_offset: bool = False,
) -> LidarSolution:
    """Levenberg-Marquardt (core.lm, dense) over T_lidar_cam, a range bias per laser (prior: the ring runs'
    shared scatter, since a laser's bias is the same at every pose), every T_cam_board (prior: its image
    covariance) and optionally one range offset for all lasers. The state is (T_lidar_cam, the biases and
    offset, the (n, 6) camera-pose perturbations); T_lidar_cam is re-linearised at every step."""
    lasers = 1 + max(int(max(p.lidar.ring_of_point.max(), p.lidar.edge_ring.max(initial=0))) for p in poses)
    layout = _Layout(lasers, estimate_range_offset)
    n_g, n = layout.size, len(poses)
    laser_prior = np.zeros(n_g)
    laser_prior[6 : 6 + lasers] = 1.0 / max(noise.run_bias_m, 1e-4)
    priors = [np.linalg.cholesky(np.linalg.inv(p.camera.covariance)).T for p in poses]
    runs = [_runs_of(p) for p in poses]
    State = tuple[np.ndarray, np.ndarray, np.ndarray]

    def build(state: State) -> tuple[np.ndarray, np.ndarray, float, int]:
        """(H, J^T rho, rho^T rho, residual count) of the whitened residuals rho (predicted - observed)."""
        T0, extra, loc = state
        xg_ = np.concatenate([np.zeros(6), extra])
        H = np.pad(np.diag(laser_prior**2), (0, 6 * n))
        g = np.zeros(n_g + 6 * n)
        g[:n_g] = laser_prior**2 * xg_
        cost, m = float(np.sum((laser_prior * xg_) ** 2)), 0
        biases, offset = layout.split(xg_)
        for i, p in enumerate(poses):

            def whitened(xk: np.ndarray, lk: np.ndarray, i: int = i, p: Pose = p) -> np.ndarray:
                return _whitened(xk, layout, T0, p, board, lk, noise, priors[i], runs[i])

            r0 = whitened(xg_, loc[i])
            J = np.zeros((r0.size, n_g + 6))
            dp, de = range_derivatives(T0, perturb(p.camera.T_cam_board, loc[i]), p, board, offset, biases)
            n_p, n_e = len(dp), len(de)
            for k in range(6, n_g):  # range columns, exact: one laser's bias, or the shared offset
                mask_p = np.ones(n_p) if k == 6 + lasers else (p.lidar.ring_of_point == k - 6).astype(float)
                mask_e = np.ones(n_e) if k == 6 + lasers else (p.lidar.edge_ring == k - 6).astype(float)
                J[:n_p, k] = _whiten(dp * mask_p, runs[i], noise)
                J[n_p : n_p + n_e, k] = de * mask_e / noise.edge_m
            for k in [*range(6), *range(n_g, n_g + 6)]:
                xk, lk = xg_.copy(), loc[i].copy()
                if k < n_g:
                    xk[k] += 1e-7
                else:
                    lk[k - n_g] += 1e-7
                J[:, k] = (whitened(xk, lk) - r0) / 1e-7
            cols = np.r_[np.arange(n_g), n_g + 6 * i + np.arange(6)]
            H[np.ix_(cols, cols)] += J.T @ J
            g[cols] += J.T @ r0
            cost += float(r0 @ r0)
            m += r0.size
        return H, g, cost, m

    def evaluate(state: State) -> DenseSystem:
        H, g, cost, _ = build(state)
        return DenseSystem(cost, H, -g)  # core.lm's g is J^T (observed - predicted)

    def retract(state: State, delta: np.ndarray) -> State:
        T0, extra, loc = state
        return perturb(T0, delta[:6]), extra + delta[6:n_g], loc + delta[n_g:].reshape(n, 6)

    fit = solve_lm(
        evaluate,
        (T_start.copy(), np.zeros(n_g - 6), np.zeros((n, 6))),
        retract,
        damping=DAMPING,
        max_iterations=MAX_ITERATIONS,
        relative_tolerance=STEP_TOL,
        label="the camera-LiDAR solve",
        hint="check the station box and the camera's calibration",
    )
    T0, extra, locals_ = fit.params
    H, _, cost, m = build(fit.params)
    dof = m - 6 * (n + 1) - int(estimate_range_offset)
    if dof <= 0 or not np.isfinite(cost):
        raise NumericalError(
            f"camera-LiDAR solve has {m} residuals for {n_g + 6 * n} unknowns", "capture more poses"
        )
    try:
        cov_all = np.linalg.inv(H) * max(cost / dof, 1.0)
    except np.linalg.LinAlgError:
        raise NumericalError("camera-LiDAR normal equations are singular", "vary the board's tilt") from None
    biases, offset = layout.split(np.concatenate([np.zeros(6), extra]))
    plane_all, edge_all, per_pose = [], [], []
    for i, p in enumerate(poses):
        pr, er = pose_residuals(T0, perturb(p.camera.T_cam_board, locals_[i]), p, board, offset, biases)
        plane_all.append(pr)
        edge_all.append(er)
        per_pose.append(float(np.sqrt(np.mean(pr**2))))
    return LidarSolution(
        T0,
        cov_all[:6, :6],
        offset,
        float(np.sqrt(cov_all[-1, -1])) if estimate_range_offset else None,
        float(np.sqrt(np.mean(np.concatenate(plane_all) ** 2))),
        float(np.sqrt(np.mean(np.concatenate(edge_all) ** 2))),
        tuple(per_pose),
        noise,
        fit.iterations,
        laser_bias_m=biases.copy(),
    )


def pose_excess(
    poses: Sequence[Pose],
    T_lidar_cam: np.ndarray,
    noise: NoiseModel,
    laser_bias_m: np.ndarray | None = None,
    range_offset_m: float = 0.0,
) -> tuple[float, float]:
    """Pose-level scatter the point noise does not explain: (offset sigma m, tilt sigma rad).

    Per pose, the board points in the camera-seen board frame are fitted with z = a + b x + c y; the
    spread of a (offset) and of b, c (tilt) over poses, less what the noise model predicts for them
    (the coefficients' covariance through the same whitening), is what neither sensor's own noise
    accounts for: lens-model error, board flatness. The points are first corrected by the solved per-laser
    biases and range offset (those are modelled already and must not be counted twice). It goes into
    each camera pose's prior, so the answer's sigma carries it (tests/core/lidar/test_render_honesty.py).
    """
    offs: list[float] = []
    tilts: list[float] = []
    v_off: list[float] = []
    v_tilt: list[float] = []
    for p in poses:
        T_bl = se3.invert(T_lidar_cam @ p.camera.T_cam_board)
        corr = range_offset_m + (0.0 if laser_bias_m is None else laser_bias_m[p.lidar.ring_of_point])
        q = _corrected(p.lidar.points_m, corr) @ T_bl[:3, :3].T + T_bl[:3, 3]
        centre = q[:, :2].mean(axis=0)
        A = np.column_stack([np.ones(len(q)), q[:, 0] - centre[0], q[:, 1] - centre[1]])
        runs = _runs_of(p)
        Aw = np.column_stack([_whiten(A[:, k], runs, noise) for k in range(3)])
        coef = np.linalg.lstsq(Aw, _whiten(q[:, 2], runs, noise), rcond=None)[0]
        cov = np.linalg.inv(Aw.T @ Aw)
        offs.append(coef[0] ** 2)
        v_off.append(cov[0, 0])
        tilts.extend(coef[1:] ** 2)
        v_tilt.extend(np.diag(cov)[1:])
    n = len(poses)
    shrink = n / max(n - 3, 1)  # the solve itself absorbed part of the pose-level scatter
    off2 = float(shrink * np.mean(offs) - np.mean(v_off))
    tilt2 = float(shrink * np.mean(tilts) - np.mean(v_tilt))
    return float(np.sqrt(max(off2, 0.0))), float(np.sqrt(max(tilt2, 0.0)))


def inflate_camera(pose: Pose, board: BackingBoard, offset_m: float, tilt_rad: float) -> Pose:
    """``pose`` with its camera prior widened by a board offset along its normal and tilts about its
    centre."""
    T = pose.camera.T_cam_board
    R, t = T[:3, :3], T[:3, 3]
    c = T[:3, :3] @ board.centre_in_pattern() + t
    G = np.zeros((6, 3))
    G[3:, 0] = R[:, 2] * offset_m
    for k in (0, 1):  # rotation about the board's x / y axis through its centre: dt = dphi x (t - c)
        a = R[:, k] * tilt_rad
        G[:3, k + 1] = a
        G[3:, k + 1] = np.cross(a, t - c)
    cam = pose.camera
    widened = type(cam)(cam.T_cam_board, cam.covariance + G @ G.T, cam.rms_px)
    return Pose(pose.label, widened, pose.lidar)


def solve(poses: Sequence[Pose], board: BackingBoard, estimate_range_offset: bool = False) -> LidarSolution:
    """Closed form; noise model from its residuals; joint solve; noise and pose-level scatter re-estimated
    (``pose_excess``, carried in through the camera priors) and solved once more. OpenBLAS on one thread:
    its workers spin on these small products (20 poses: 0.6 s of CPU on one thread, 4.8 s with them)."""
    with single_threaded_blas():
        try:
            return _solve(poses, board, estimate_range_offset)
        except np.linalg.LinAlgError as exc:  # a prior or normal matrix that is not positive definite
            raise NumericalError(
                f"the camera-LiDAR solve broke down ({exc}): the board poses the camera gives and the planes "
                "the LiDAR measures cannot be one rigid transform",
                "check the board's square size, --cols / --rows and the scan box",
            ) from exc


def _solve(poses: Sequence[Pose], board: BackingBoard, estimate_range_offset: bool) -> LidarSolution:
    T = closed_form(poses, board)
    own = [p.lidar.points_m @ p.lidar.normal - p.lidar.distance_m for p in poses]
    noise = estimate_noise(poses, own, EDGE_SIGMA_START_M)
    first = joint_solve(poses, board, T, noise, estimate_range_offset)
    plane, edge = zip(
        *(
            pose_residuals(first.T_lidar_cam, p.camera.T_cam_board, p, board, first.range_offset_m)
            for p in poses
        ),
        strict=True,
    )
    edges = np.concatenate(edge)
    # robust scale of the edge residuals: a few end points near a corner sit on the wrong side
    noise = estimate_noise(poses, list(plane), float(1.4826 * np.median(np.abs(edges - np.median(edges)))))
    offset_m, tilt_rad = pose_excess(
        poses, first.T_lidar_cam, noise, first.laser_bias_m, first.range_offset_m
    )
    widened = [inflate_camera(p, board, offset_m, tilt_rad) for p in poses]
    final = joint_solve(widened, board, first.T_lidar_cam, noise, estimate_range_offset)
    return replace(final, pose_offset_sigma_m=offset_m, pose_tilt_sigma_rad=tilt_rad)
