"""Seeded camera + IMU recordings with known T_imu_cam, td, biases, noise and line delay (no images).

The board (a flat grid of points, board frame w: x right, y down, z into the board) hangs on a wall:
gravity is +y in w. The camera keeps looking at the board's centre from ``distance_m`` while it turns:
R_w_cam(t) = Exp(phi(t)) and its centre c(t) = centre - R_w_cam(t) [0, 0, d] + a small translation
wiggle. Motions:

- ``"dance"``: phi is a sum of sines on all three axes at different frequencies (rate reversals on
  every axis, what a calibration needs);
- ``"corridor"``: phi = omega t about the optical axis at a constant rate, no wiggle: smooth
  constant-rate motion, the (td, rotation) degenerate case of seed chapter 3; ``corridor_wobble_rad_s``
  swings the rate by that much at 0.5 Hz (nearly degenerate: the cross-correlation finds a peak).

The IMU rides on the camera: T_w_imu = T_w_cam T_imu_cam^-1. Its gyro is the body rate of R_w_imu
(log of R(t - h)^T R(t + h) / 2h), its accelerometer R_imu_w (p'' - g_w) (five-point second
difference), both plus constant biases and white noise of density * sqrt(rate) (Kalibr's discrete
convention). Clocks: the IMU clock is the truth's; a frame stamped t_cam was seen at t_cam + td_s
(+ line_delay_s * (v - c_y) for a corner on row v, solved by fixed-point iteration). Corners get
Gaussian noise of ``noise_px``; corners off the image are dropped. Further cameras
(``more_cameras``: their T_imu_cam) share the lens, the frame stamps and td (one rig clock) and are
rendered after everything else, so adding one leaves the first camera and the IMU unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics import se3
from calibctl.core.intrinsics.lens_checks import distort_normalised

EUROC_LIKE_T_IMU_CAM = se3.transform(
    np.array([[0.0149, -0.9999, 0.0041], [0.9996, 0.0150, 0.0257], [-0.0258, 0.0038, 0.9997]]),
    [-0.0216, -0.0647, 0.0098],
)
# EuRoC's stereo pair: the second camera 11 cm along the first one's x, nearly parallel.
EUROC_LIKE_T_CAM0_CAM1 = se3.transform(
    se3.rotation_from_rotvec([0.0141, -0.0004, 0.0023]), [0.110, -0.0002, 0.0009]
)


@dataclass(frozen=True)
class ImuCameraTruth:
    """T_imu_cam (4, 4); td_s (t_imu = t_cam + td_s); line_delay_s (s per row from c_y);
    gyro_bias_rad_s, accel_bias_m_s2 (3,); gravity_w_m_s2 (3,) in the board frame; the noise used:
    gyro_noise_density (rad/s/sqrt(Hz)), accel_noise_density (m/s^2/sqrt(Hz)), noise_px."""

    T_imu_cam: np.ndarray
    td_s: float
    line_delay_s: float
    gyro_bias_rad_s: np.ndarray
    accel_bias_m_s2: np.ndarray
    gravity_w_m_s2: np.ndarray
    gyro_noise_density: float
    accel_noise_density: float
    noise_px: float


@dataclass(frozen=True)
class RenderedCamera:
    """A further camera of the rig: T_imu_cam (4, 4) and its corners per frame (the first camera's
    stamps, lens and td)."""

    T_imu_cam: np.ndarray
    object_points: tuple[np.ndarray, ...]
    image_points: tuple[np.ndarray, ...]


@dataclass(frozen=True)
class ImuCameraRecording:
    """imu_t_s (n,), gyro_rad_s (n, 3), accel_m_s2 (n, 3): IMU clock. cam_t_s (F,): camera clock;
    object_points / image_points: F arrays (N_f, 3) m / (N_f, 2) px. camera_matrix (3, 3),
    dist_coeffs (k,), image_size (w, h). truth: what produced it. more_cameras: the rig's further
    cameras (``more_cameras`` of ``synthesize_imu_camera``)."""

    imu_t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    cam_t_s: np.ndarray
    object_points: tuple[np.ndarray, ...]
    image_points: tuple[np.ndarray, ...]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    truth: ImuCameraTruth
    more_cameras: tuple[RenderedCamera, ...] = ()


def grid_points(cols: int = 7, rows: int = 6, spacing_m: float = 0.05) -> np.ndarray:
    """(cols * rows, 3) board points, z = 0, row-major."""
    x, y = np.meshgrid(np.arange(cols) * spacing_m, np.arange(rows) * spacing_m)
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)


class _Motion:
    def __init__(
        self, kind: str, rng: np.random.Generator, centre: np.ndarray, distance_m: float, wobble_rad_s: float
    ) -> None:
        if kind not in ("dance", "corridor"):
            raise ValueError(f"motion must be 'dance' or 'corridor', not {kind!r}")
        self.kind, self.centre, self.d = kind, centre, distance_m
        self.amp = rng.uniform(0.25, 0.4, 3) * np.array([1.0, 1.0, 1.2])
        self.freq = rng.uniform(0.4, 0.9, 3) * np.array([1.0, 1.3, 0.8])
        self.phase = rng.uniform(0, 2 * np.pi, 3)
        self.wiggle = rng.uniform(0.03, 0.06, 3)
        self.wfreq = rng.uniform(0.3, 0.7, 3)
        self.wphase = rng.uniform(0, 2 * np.pi, 3)
        self.rate = 0.6  # rad/s, the corridor's constant rate
        self.wobble = wobble_rad_s  # amplitude of a 0.5 Hz swing of the corridor's rate

    def pose(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """R_w_cam (m, 3, 3), c_w (m, 3)."""
        t = np.asarray(t, np.float64)
        if self.kind == "corridor":
            w = 2 * np.pi * 0.5
            angle = self.rate * t + self.wobble / w * (1 - np.cos(w * t))
            phi = np.stack([0 * t, 0 * t, angle], axis=1)
            wiggle = np.zeros((t.size, 3))
        else:
            phi = self.amp * np.sin(2 * np.pi * self.freq * t[:, None] + self.phase)
            wiggle = self.wiggle * np.sin(2 * np.pi * self.wfreq * t[:, None] + self.wphase)
        R = se3.rotations_from_rotvecs(phi)
        c = self.centre - R @ np.array([0.0, 0.0, self.d]) + wiggle
        return R, c


def _imu_pose(motion: _Motion, T_cam_imu: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    R_w_c, c = motion.pose(t)
    return R_w_c @ T_cam_imu[:3, :3], c + R_w_c @ T_cam_imu[:3, 3]


def _project(Xc: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    xd, yd, _ = distort_normalised(Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2], dist)
    return np.stack([K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


@dataclass(frozen=True)
class _Render:
    """What every camera of one recording shares: the motion, lens, board, clock and corner noise."""

    motion: _Motion
    T_imu_cam0: np.ndarray
    K: np.ndarray
    dist: np.ndarray
    obj: np.ndarray
    image_size: tuple[int, int]
    td_s: float
    line_delay_s: float
    noise_px: float

    def frames(
        self, T_imu_cam: np.ndarray, t_cam: np.ndarray, rng: np.random.Generator
    ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """Board points and noisy corners per frame of the camera at T_imu_cam (module docstring)."""
        K, obj = self.K, self.obj
        # The motion is the first camera's; a further camera rides on it through the IMU.
        T_c0_c = se3.invert(self.T_imu_cam0) @ T_imu_cam
        first = T_imu_cam is self.T_imu_cam0
        objs, imgs = [], []
        w, hgt = self.image_size
        for tc in t_cam:
            rows = np.full(obj.shape[0], K[1, 2])
            for _ in range(4 if self.line_delay_s else 1):
                t_true = tc + self.td_s + self.line_delay_s * (rows - K[1, 2])
                R_w_c, c = self.motion.pose(t_true)
                if not first:
                    R_w_c, c = R_w_c @ T_c0_c[:3, :3], c + R_w_c @ T_c0_c[:3, 3]
                Xc = np.einsum("nji,nj->ni", R_w_c, obj - c)
                px = _project(Xc, K, self.dist)
                rows = px[:, 1]
            px = px + self.noise_px * rng.standard_normal(px.shape)
            inside = (Xc[:, 2] > 0.05) & (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < hgt)
            objs.append(obj[inside])
            imgs.append(px[inside])
        return tuple(objs), tuple(imgs)


def synthesize_imu_camera(
    seed: int = 0,
    *,
    motion: str = "dance",
    duration_s: float = 6.0,
    camera_rate_hz: float = 20.0,
    imu_rate_hz: float = 200.0,
    T_imu_cam: np.ndarray = EUROC_LIKE_T_IMU_CAM,
    td_s: float = 0.012,
    line_delay_s: float = 0.0,
    gyro_bias_rad_s: tuple[float, float, float] = (0.002, -0.003, 0.001),
    accel_bias_m_s2: tuple[float, float, float] = (0.05, -0.03, 0.08),
    gyro_noise_density: float = 1.7e-4,
    accel_noise_density: float = 2.0e-3,
    noise_px: float = 0.3,
    distance_m: float = 0.6,
    camera_matrix: np.ndarray | None = None,
    dist_coeffs: np.ndarray | None = None,
    image_size: tuple[int, int] = (752, 480),
    board_points: np.ndarray | None = None,
    corridor_wobble_rad_s: float = 0.0,
    more_cameras: tuple[np.ndarray, ...] = (),
    imu_scale_misalignment: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> ImuCameraRecording:
    """A camera + IMU recording (module docstring); everything from numpy.random.default_rng(seed).

    ``imu_scale_misalignment``: (M_gyro, C_gyro_i, A_gyro, M_accel), each (3, 3), Kalibr's
    scale-misalignment IMU: the gyro reads M_gyro C_gyro_i w + A_gyro C_gyro_i a and the accelerometer
    M_accel a (w, a: the true body rate and specific force), before biases and noise."""
    rng = np.random.default_rng(seed)
    K = (
        camera_matrix
        if camera_matrix is not None
        else np.array([[458.0, 0, 367.0], [0, 457.0, 248.0], [0, 0, 1]])
    )
    dist = dist_coeffs if dist_coeffs is not None else np.array([-0.28, 0.074, 0.0002, 0.00002])
    obj = board_points if board_points is not None else grid_points()
    centre = obj.mean(axis=0)
    mot = _Motion(motion, rng, centre, distance_m, corridor_wobble_rad_s)
    T_cam_imu = se3.invert(T_imu_cam)
    g_w = np.array([0.0, 9.80665, 0.0])
    # IMU: starts 0.3 s before the first frame and ends 0.3 s after the last (both on the IMU clock).
    t_imu = -0.3 + np.arange(int(round((duration_s + 0.6) * imu_rate_hz))) / imu_rate_hz
    h = 1e-4
    Rm, _ = _imu_pose(mot, T_cam_imu, t_imu - h)
    Rp, _ = _imu_pose(mot, T_cam_imu, t_imu + h)
    gyro = se3.rotvecs_from_rotations(np.einsum("nji,njk->nik", Rm, Rp)) / (2 * h)
    hh = 2e-3
    pos = [_imu_pose(mot, T_cam_imu, t_imu + k * hh)[1] for k in (-2, -1, 0, 1, 2)]
    p_dd = (-pos[0] + 16 * pos[1] - 30 * pos[2] + 16 * pos[3] - pos[4]) / (12 * hh**2)
    R_w_i, _ = _imu_pose(mot, T_cam_imu, t_imu)
    accel = np.einsum("nji,nj->ni", R_w_i, p_dd - g_w)
    if imu_scale_misalignment is not None:
        M_g, C_gi, A_g, M_a = (np.asarray(m, np.float64) for m in imu_scale_misalignment)
        gyro, accel = (gyro @ C_gi.T @ M_g.T + accel @ C_gi.T @ A_g.T, accel @ M_a.T)
    sg, sa = gyro_noise_density * np.sqrt(imu_rate_hz), accel_noise_density * np.sqrt(imu_rate_hz)
    gyro = gyro + np.asarray(gyro_bias_rad_s) + sg * rng.standard_normal(gyro.shape)
    accel = accel + np.asarray(accel_bias_m_s2) + sa * rng.standard_normal(accel.shape)
    # Camera frames, stamped on the camera clock.
    t_cam = np.arange(int(round(duration_s * camera_rate_hz))) / camera_rate_hz
    render = _Render(mot, T_imu_cam, K, dist, obj, image_size, td_s, line_delay_s, noise_px)
    objs, imgs = render.frames(T_imu_cam, t_cam, rng)
    more = tuple(
        RenderedCamera(np.asarray(T, np.float64), *render.frames(T, t_cam, rng)) for T in more_cameras
    )
    truth = ImuCameraTruth(
        np.asarray(T_imu_cam, np.float64),
        td_s,
        line_delay_s,
        np.asarray(gyro_bias_rad_s, np.float64),
        np.asarray(accel_bias_m_s2, np.float64),
        g_w,
        gyro_noise_density,
        accel_noise_density,
        noise_px,
    )
    return ImuCameraRecording(t_imu, gyro, accel, t_cam, objs, imgs, K, dist, image_size, truth, more)
