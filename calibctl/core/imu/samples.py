"""The recording the camera-IMU estimator reads: IMU samples, the IMU noise model, camera frames.

Checked on construction; every refusal is a ``ValueError`` subclass whose text names the fault and
the fix (the workflow maps them to ``CalibctlError``). Times are seconds on each sensor's own clock
(the readers convert nanosecond stamps); the estimator relates the clocks by ``t_imu = t_cam + td_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GRAVITY_M_S2 = 9.80665
DEG_PER_RAD = 180.0 / np.pi
# A hand-held or robot calibration dance stays well under 10 rad/s (573 deg/s); a gyro logging deg/s
# reaches that at a gentle 10 deg/s... so the 99th percentile of |w| above it reads as deg/s.
MAX_PLAUSIBLE_RATE_RAD_S = 10.0
# |accel| at rest is 9.81 m/s^2; an accelerometer logging g has a median |a| near 1.
G_UNIT_BAND = (0.5, 2.0)
M_S2_BAND = (4.0, 30.0)
GAP_FACTOR = 2.5  # an interval above this many median periods is a gap (a dropped sample or frame)
PLATEAU_SAMPLES = 3  # this many consecutive samples pinned at one axis' extreme reads as clipping


class ImuInputError(ValueError):
    """The IMU or camera recording cannot be used as it is (the message names the fix)."""


class StampOrderError(ImuInputError):
    """Stamps not strictly increasing (duplicated, reordered or overlapping)."""


class ImuUnitError(ImuInputError):
    """An IMU channel is in the wrong unit (deg/s for rad/s, g for m/s^2)."""


@dataclass(frozen=True)
class ImuNoise:
    """Kalibr imu.yaml fields (continuous-time densities), SI units.

    gyro_noise_density: rad/s/sqrt(Hz); accel_noise_density: m/s^2/sqrt(Hz);
    gyro_random_walk: rad/s^2/sqrt(Hz); accel_random_walk: m/s^3/sqrt(Hz).
    The discrete one-sample sigma at rate f is density * sqrt(f) (Kalibr's convention).
    """

    gyro_noise_density: float
    accel_noise_density: float
    gyro_random_walk: float
    accel_random_walk: float
    gravity_m_s2: float = GRAVITY_M_S2

    def __post_init__(self) -> None:
        for name in ("gyro_noise_density", "accel_noise_density", "gyro_random_walk", "accel_random_walk"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ImuInputError(
                    f"IMU noise {name} = {value!r} must be a positive number (Kalibr imu.yaml)"
                )


def _check_increasing(t_s: np.ndarray, what: str) -> None:
    if t_s.ndim != 1 or t_s.size < 2:
        raise ImuInputError(f"{what}: need at least 2 stamps, got {t_s.size}")
    if not np.isfinite(t_s).all():
        raise ImuInputError(f"{what}: stamps contain NaN or infinity")
    steps = np.diff(t_s)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0])
        raise StampOrderError(
            f"{what}: stamps are not strictly increasing ({bad.size} times; first at sample {i + 1}: "
            f"{t_s[i]:.9f} s then {t_s[i + 1]:.9f} s); sort the log and drop duplicated or overlapping "
            "stamps before calibrating"
        )


def median_period_s(t_s: np.ndarray) -> float:
    return float(np.median(np.diff(t_s)))


def gaps(t_s: np.ndarray, factor: float = GAP_FACTOR) -> np.ndarray:
    """(k, 2) float64 [start, end] seconds of every interval longer than ``factor`` median periods."""
    steps = np.diff(t_s)
    at = np.flatnonzero(steps > factor * median_period_s(t_s))
    return np.stack([t_s[at], t_s[at + 1]], axis=1) if at.size else np.zeros((0, 2))


@dataclass(frozen=True)
class ImuSamples:
    """IMU log on the IMU clock.

    Attributes:
        t_s: (n,) float64 seconds, strictly increasing.
        gyro_rad_s: (n, 3) angular rate in the IMU frame, rad/s.
        accel_m_s2: (n, 3) specific force in the IMU frame, m/s^2 (about +9.81 up at rest).
        gyro_range_rad_s, accel_range_m_s2: the sensor's full scale when known (saturation check).
    """

    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    gyro_range_rad_s: float | None = None
    accel_range_m_s2: float | None = None

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, np.float64)
        w = np.asarray(self.gyro_rad_s, np.float64)
        a = np.asarray(self.accel_m_s2, np.float64)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "gyro_rad_s", w)
        object.__setattr__(self, "accel_m_s2", a)
        if w.shape != (t.size, 3) or a.shape != (t.size, 3):
            raise ImuInputError(
                f"IMU: gyro {w.shape} and accel {a.shape} must both be ({t.size}, 3) like the stamps"
            )
        _check_increasing(t, "IMU")
        if not (np.isfinite(w).all() and np.isfinite(a).all()):
            raise ImuInputError("IMU: gyro or accel contains NaN or infinity; drop those samples")
        check_units(w, a)

    @property
    def rate_hz(self) -> float:
        return 1.0 / median_period_s(self.t_s)

    def saturated(self) -> tuple[np.ndarray, np.ndarray]:
        """(n,) bool masks of gyro and accel samples at full scale (known range) or pinned at an
        axis' extreme for ``PLATEAU_SAMPLES`` consecutive samples (clipping)."""
        return (
            _saturated(self.gyro_rad_s, self.gyro_range_rad_s),
            _saturated(self.accel_m_s2, self.accel_range_m_s2),
        )


def _saturated(x: np.ndarray, full_scale: float | None) -> np.ndarray:
    mask = np.zeros(x.shape[0], bool)
    if full_scale is not None:
        mask |= (np.abs(x) >= 0.999 * full_scale).any(axis=1)
    for axis in range(3):
        col = x[:, axis]
        for extreme in (col.max(), col.min()):
            if extreme == 0:
                continue
            at = col == extreme
            if at.sum() < PLATEAU_SAMPLES:
                continue
            run = np.convolve(at.astype(int), np.ones(PLATEAU_SAMPLES, int), "valid") == PLATEAU_SAMPLES
            hit = np.zeros_like(at)
            for k in range(PLATEAU_SAMPLES):
                hit[k : k + run.size] |= run
            mask |= hit
    return mask


def check_units(gyro: np.ndarray, accel: np.ndarray) -> None:
    """Refuse a gyro logging deg/s or an accelerometer logging g, from magnitudes alone.

    Raises:
        ImuUnitError: naming the unit found and the factor that converts it.
    """
    rate = np.linalg.norm(gyro, axis=1)
    p99 = float(np.percentile(rate, 99))
    if p99 > MAX_PLAUSIBLE_RATE_RAD_S:
        raise ImuUnitError(
            f"IMU gyro: 99% of |w| up to {p99:.1f}, above {MAX_PLAUSIBLE_RATE_RAD_S:g} rad/s "
            f"({MAX_PLAUSIBLE_RATE_RAD_S * DEG_PER_RAD:.0f} deg/s): the gyro reads deg/s; multiply by "
            "pi/180 to give rad/s"
        )
    norm = float(np.median(np.linalg.norm(accel, axis=1)))
    if G_UNIT_BAND[0] <= norm <= G_UNIT_BAND[1]:
        raise ImuUnitError(
            f"IMU accelerometer: median |a| = {norm:.3f}, about 1: it reads g; multiply by "
            f"{GRAVITY_M_S2} to give m/s^2"
        )
    if not M_S2_BAND[0] <= norm <= M_S2_BAND[1]:
        raise ImuUnitError(
            f"IMU accelerometer: median |a| = {norm:.3f} is neither about 9.81 (m/s^2) nor about 1 (g); "
            "check the unit and the column order of the log"
        )


def check_rate_ratio(gyro_std_rad_s: float, camera_std_rad_s: float) -> None:
    """Refuse a gyro whose rate swings ~57 times the camera's (deg/s read as rad/s).

    Raises:
        ImuUnitError: the gyro and camera rates differ by the deg/rad factor.
    """
    if camera_std_rad_s <= 0:
        return
    ratio = gyro_std_rad_s / camera_std_rad_s
    if 0.6 * DEG_PER_RAD <= ratio <= 1.4 * DEG_PER_RAD:
        raise ImuUnitError(
            f"IMU gyro: its rate varies {ratio:.1f} times as much as the camera's rotation rate (57.3 "
            "would be deg/s against rad/s): the gyro reads deg/s; multiply by pi/180 to give rad/s"
        )


@dataclass(frozen=True)
class CameraFrames:
    """Board corners per camera frame, on the camera clock.

    Attributes:
        t_s: (F,) float64 seconds, strictly increasing (one stamp per frame).
        object_points: F arrays (N_f, 3) float64, board frame, metres.
        image_points: F arrays (N_f, 2) float64 px (undistorted by nothing: raw detections).
        camera_matrix: (3, 3) float64 held intrinsics; dist_coeffs: (k,) OpenCV order.
        image_size: (width, height) px.
    """

    t_s: np.ndarray
    object_points: tuple[np.ndarray, ...]
    image_points: tuple[np.ndarray, ...]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, np.float64)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "camera_matrix", np.asarray(self.camera_matrix, np.float64))
        object.__setattr__(self, "dist_coeffs", np.asarray(self.dist_coeffs, np.float64).ravel())
        object.__setattr__(
            self, "object_points", tuple(np.ascontiguousarray(p, np.float64) for p in self.object_points)
        )
        object.__setattr__(
            self, "image_points", tuple(np.ascontiguousarray(p, np.float64) for p in self.image_points)
        )
        if not len(self.object_points) == len(self.image_points) == t.size:
            raise ImuInputError(
                f"camera: {t.size} stamps, {len(self.object_points)} board-point sets and "
                f"{len(self.image_points)} corner sets must match one per frame"
            )
        _check_increasing(t, "camera")
        for f, (obj, img) in enumerate(zip(self.object_points, self.image_points, strict=True)):
            if obj.ndim != 2 or obj.shape[1] != 3 or img.shape != (obj.shape[0], 2):
                raise ImuInputError(f"camera frame {f}: board points {obj.shape} and corners {img.shape}")

    @property
    def rate_hz(self) -> float:
        return 1.0 / median_period_s(self.t_s)
