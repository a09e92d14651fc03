"""Fault injector: synthetic residual buffers, odometry logs and rate logs with one known fault.

The residual bench is the seed's chapter 5 rig (f = 800 px, 1280x960, six structures at 1, 2, 5,
10, 20 and 50 m with nominal image radii 80..460 px and per-structure yaw rates 0.225..0.575 rad/s),
extended so that a per-keyframe fit has something to fit: the robot slaloms (each keyframe scales
the yaw rates by its own factor), the scene moves across the image as it turns (each keyframe shifts
the structure's radius), and each keyframe sees one of the six structures. 500 keyframes by default:
the seed's 500-keyframe ring buffer.

Residual model (paraxial, exactly as the seed's bench; residual = observed - predicted, px):

    focal           eps * r                   magnitude = df/f            (seed: 0.02)
    k1              k1 * r^3 / f^2            magnitude = k1 error        (seed: 0.02)
    principal-point dcx                       magnitude = px              (seed: 10)
    rotation        f * tan(dtheta)           magnitude = degrees         (seed: 1.0)
    translation     f * dt / Z                magnitude = lever arm, m    (seed: 0.02)
    time-offset     td * image_speed          magnitude = s               (seed: 0.0184)
    rolling-shutter t_line * speed * row      magnitude = s per row       (seed: 20e-6)
    gauge           0 (no residual at all)    magnitude = believed/true   (seed: 23/25 = 0.92)

plus noise of total standard deviation noise_px per feature, of which a part is shared by every
feature of a keyframe so that they correlate at rho = 0.05 (a pose error moves them together; the
seed's design-effect example; this is why triage aggregates per keyframe).
"""

from __future__ import annotations

import math

import numpy as np

FOCAL_PX = 800.0
IMAGE_ROWS = 960
STRUCTURE_RANGE_M = np.array([1.0, 2.0, 5.0, 10.0, 20.0, 50.0])
STRUCTURE_RADIUS_PX = np.array([80.0, 160.0, 240.0, 320.0, 400.0, 460.0])
STRUCTURE_YAW_RATE_RAD_S = np.array([0.300, 0.575, 0.275, 0.225, 0.575, 0.300])

KEYFRAME_CORR = 0.05  # seed chapter 4: intra-keyframe correlation rho of residuals sharing one pose
FAULTS = (
    "focal",
    "k1",
    "principal-point",
    "rotation",
    "translation",
    "time-offset",
    "rolling-shutter",
    "gauge",
)
DEFAULT_MAGNITUDE = {
    "focal": 0.02,
    "k1": 0.02,
    "principal-point": 10.0,
    "rotation": 1.0,
    "translation": 0.02,
    "time-offset": 0.0184,
    "rolling-shutter": 20e-6,
    "gauge": 23.0 / 25.0,
}
MAGNITUDE_UNIT = {
    "focal": "df/f",
    "k1": "k1",
    "principal-point": "px",
    "rotation": "deg",
    "translation": "m",
    "time-offset": "s",
    "rolling-shutter": "s/row",
    "gauge": "believed/true scale",
}


def fault_residual_px(
    fault: str,
    magnitude: float,
    radius_px: np.ndarray,
    inv_range_per_m: np.ndarray,
    image_speed_px_s: np.ndarray,
    row: np.ndarray,
    focal_px: float = FOCAL_PX,
) -> np.ndarray:
    """Noise-free residual (px) that ``fault`` of size ``magnitude`` leaves on each feature; arrays (n,)."""
    r = np.asarray(radius_px, dtype=np.float64)
    zeros = np.zeros_like(r)
    if fault == "focal":
        return magnitude * r
    if fault == "k1":
        return magnitude * r**3 / focal_px**2
    if fault == "principal-point":
        return zeros + magnitude
    if fault == "rotation":
        return zeros + focal_px * math.tan(math.radians(magnitude))
    if fault == "translation":
        return focal_px * magnitude * np.asarray(inv_range_per_m, dtype=np.float64)
    if fault == "time-offset":
        return magnitude * np.asarray(image_speed_px_s, dtype=np.float64)
    if fault == "rolling-shutter":
        return magnitude * np.asarray(image_speed_px_s, dtype=np.float64) * np.asarray(row, dtype=np.float64)
    if fault in ("gauge", "none"):
        return zeros
    raise ValueError(f"unknown fault {fault!r}; expected one of {', '.join(FAULTS)}")


def synth_residual_buffer(
    fault: str,
    magnitude: float,
    noise_px: float = 0.3,
    seed: int = 0,
    n_keyframes: int = 500,
    features_per_keyframe: int = 80,
    keyframe_corr: float = KEYFRAME_CORR,
    n_cameras: int = 1,
    focal_px: float = FOCAL_PX,
) -> dict[str, np.ndarray]:
    """A residual buffer in the triage format. The fault is injected into camera "cam0" only.

    Each keyframe sees one of the six structures (features cluster on the structure in view), its
    radius shifted by the keyframe's yaw, its image speed scaled by the keyframe's slalom factor.
    The per-feature noise is split so that features of one keyframe correlate at ``keyframe_corr``
    (the seed's rho = 0.05): shared sigma = noise_px * sqrt(rho / (1 - rho)).
    Returns columns (n,) each: residual_px, radius_px, image_speed_px_s, inv_range_per_m, row (int),
    keyframe (int), camera (str); n = n_cameras * n_keyframes * features_per_keyframe.
    """
    rng = np.random.default_rng(seed)
    shared_sigma = noise_px * math.sqrt(keyframe_corr / (1.0 - keyframe_corr))
    names = ("residual_px", "radius_px", "image_speed_px_s", "inv_range_per_m", "row", "keyframe", "camera")
    cols: dict[str, list[np.ndarray]] = {k: [] for k in names}
    m = features_per_keyframe
    for cam in range(n_cameras):
        phase = rng.uniform(0.0, 2.0 * math.pi)
        for k in range(n_keyframes):
            slalom = max(0.15, 1.0 + 0.6 * math.sin(2.0 * math.pi * k / 23.0 + phase) + rng.normal(0.0, 0.1))
            s = int(rng.integers(STRUCTURE_RANGE_M.size))
            r = np.clip(
                STRUCTURE_RADIUS_PX[s] + rng.uniform(-60.0, 60.0) + rng.normal(0.0, 20.0, m), 5.0, 600.0
            )
            inv_z = 1.0 / (STRUCTURE_RANGE_M[s] * np.exp(rng.normal(0.0, 0.05, m)))
            speed = focal_px * STRUCTURE_YAW_RATE_RAD_S[s] * slalom * (1.0 + rng.normal(0.0, 0.03, m))
            row = np.clip(np.rint(rng.uniform(60.0, 900.0) + rng.normal(0.0, 40.0, m)), 0, IMAGE_ROWS - 1)
            res = rng.normal(0.0, noise_px, m) * math.sqrt(1.0 - keyframe_corr) + rng.normal(
                0.0, shared_sigma
            )
            if cam == 0:
                res = res + fault_residual_px(fault, magnitude, r, inv_z, speed, row, focal_px)
            for name, val in zip(
                names, (res, r, speed, inv_z, row, np.full(m, k), np.full(m, f"cam{cam}")), strict=True
            ):
                cols[name].append(val)
    out = {name: np.concatenate(parts) for name, parts in cols.items()}
    out["row"] = out["row"].astype(np.int64)
    out["keyframe"] = out["keyframe"].astype(np.int64)
    return out


def synth_odometry(
    gauge_scale: float = 1.0,
    slip_std: float = 0.01,
    duration_s: float = 600.0,
    rate_hz: float = 50.0,
    vio_noise_std: float = 0.002,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """Wheel and VIO per-sample distances (m) for a robot driving 0.3..1.5 m/s with stops.

    ``gauge_scale`` multiplies every VIO distance (a 23 mm board believed to be 25 mm gives 0.92, so
    wheel/VIO reads 1/0.92 = 1.087). ``slip_std`` is zero-mean per-sample wheel slip. Returns t_s (n,),
    wheel_distance_m (n,) and vio_distance_m (n,), both per-sample increments.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    speed = 0.9 + 0.6 * np.sin(2.0 * math.pi * t / 47.0) * np.sin(2.0 * math.pi * t / 13.0)
    speed[(t % 90.0) > 84.0] = 0.0  # a six-second stop every ninety seconds
    step = speed / rate_hz
    wheel = step * (1.0 + rng.normal(0.0, slip_std, t.size))
    vio = step * gauge_scale * (1.0 + rng.normal(0.0, vio_noise_std, t.size))
    return {"t_s": t, "wheel_distance_m": wheel, "vio_distance_m": vio}


RATE_PROFILES = {
    # robot slalom: slow turns with reversals, 0.2..1.7 Hz
    "slalom": (np.array([0.21, 0.43, 0.71, 1.13, 1.67]), np.array([0.45, 0.30, 0.20, 0.12, 0.08])),
    # hand-held calibration dance ("a small argument with a checkerboard"): jerky reversals, 1.3..7.7 Hz
    "dance": (np.array([1.31, 2.87, 4.33, 5.93, 7.71]), np.array([0.50, 0.40, 0.30, 0.25, 0.20])),
}


def synth_rate_signal(t_s: np.ndarray, seed: int = 0, profile: str = "slalom") -> np.ndarray:
    """A yaw rate (rad/s) with reversals: five sinusoids of ``profile``, random phases; (n,)."""
    rng = np.random.default_rng(seed)
    freqs, amps = RATE_PROFILES[profile]
    phases = rng.uniform(0.0, 2.0 * math.pi, freqs.size)
    t = np.asarray(t_s, dtype=np.float64)[:, None]
    return np.sum(amps * np.sin(2.0 * math.pi * freqs * t + phases), axis=1)


def synth_rate_logs(
    td_s: float = 0.0184,
    duration_s: float = 3.0,
    gyro_hz: float = 200.0,
    camera_hz: float = 200.0,
    noise_frac: float = 0.01,
    drift_ppm: float = 0.0,
    camera_gain: float = 1.0,
    profile: str = "dance",
    seed: int = 0,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Gyro and camera-derived yaw-rate logs of one motion, the camera clock offset by ``td_s``.

    Convention (the one calibctl timeoffset reports): the camera sample stamped t measured the rate
    the gyro saw at t + td(t), with td(t) = td_s + drift_ppm * 1e-6 * t. Noise is ``noise_frac`` of the
    signal's standard deviation on each stream. Returns ({t_s, rate_rad_s}, {t_s, rate_rad_s}).
    """
    rng = np.random.default_rng(seed + 1)
    t_gyro = np.arange(0.0, duration_s, 1.0 / gyro_hz)
    t_cam = np.arange(0.0, duration_s, 1.0 / camera_hz)
    scale = float(np.std(synth_rate_signal(t_gyro, seed, profile)))
    gyro = synth_rate_signal(t_gyro, seed, profile) + rng.normal(0.0, noise_frac * scale, t_gyro.size)
    td = td_s + drift_ppm * 1e-6 * t_cam
    cam = camera_gain * synth_rate_signal(t_cam + td, seed, profile) + rng.normal(
        0.0, noise_frac * scale, t_cam.size
    )
    return {"t_s": t_gyro, "rate_rad_s": gyro}, {"t_s": t_cam, "rate_rad_s": cam}
