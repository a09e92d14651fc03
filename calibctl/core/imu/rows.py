"""The row test on a solved camera-IMU recording (seed chapters 3-4), and the series its report draws.

A time offset error moves every corner of a frame along its image velocity by the same time: the
residual along the motion, divided by the speed, is constant across image rows. A rolling shutter reads
row v at ``line_delay * (v - c_y)`` after the principal row, so that time residual ramps with the row.
``row_test`` fits ``r . u_dot / |u_dot| = |u_dot| (a + b (v - c_y))`` over the solve's inlier corners
(ordinary least squares in px: the corner noise is the same along any direction); ``b`` is the apparent
line delay (s per row) the solve left in its residuals. Its one-sigma is the larger of the fit's own
(scaled by the residual scatter) and a delete-one-block jackknife's over contiguous time blocks, because
real residuals are correlated in time. The image velocity of each corner comes from the PnP poses of the
neighbouring frames (the board point projected through both, differenced), so no spline is needed.

``report_series`` reduces a solution to what the report page plots, in equal time bins: the gyro
(bias removed) against the camera's board-derived rate carried into the IMU frame at ``t_cam + td_s``,
and the corner / gyro / accelerometer residual RMS over time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibctl.core.imu.model import project
from calibctl.core.imu.plain import BoardTrack, board_track, camera_rates
from calibctl.core.imu.samples import CameraFrames, ImuSamples
from calibctl.core.imu.solve import ImuCameraSolution

ROW_Z_SIGNIFICANT = 4.0  # |slope| over this many sigmas: rolling shutter suspected
MIN_SPEED_PX_S = 5.0  # corners slower than this carry no time information
ROW_BINS = 12
JACKKNIFE_BLOCKS = 10
SERIES_MAX_BINS = 240  # what a 960-pixel plot can show
SERIES_MIN_BIN_S = 0.05  # no finer than the spline's knots


@dataclass(frozen=True)
class RowTest:
    """slope_s_per_row: the apparent line delay left in the residuals (s per row from c_y), with
    sigma_s_per_row; offset_s: the constant time residual (a td error would show here); z: |slope| /
    sigma; significant: z over ``ROW_Z_SIGNIFICANT``. Per row bin (absolute image rows): row_px, the
    speed-weighted mean time residual time_residual_s with its sigma_s, corners per bin."""

    slope_s_per_row: float
    sigma_s_per_row: float
    offset_s: float
    z: float
    corners: int
    significant: bool
    line_delay_solved: bool
    row_px: np.ndarray
    time_residual_s: np.ndarray
    sigma_s: np.ndarray
    counts: np.ndarray

    @property
    def message(self) -> str:
        ramp = (
            f"time residual vs image row {1e6 * self.slope_s_per_row:+.3f} +/- "
            f"{1e6 * self.sigma_s_per_row:.3f} us/row ({self.z:.1f} sigma, {self.corners} corners)"
        )
        if not self.significant:
            return f"{ramp}: constant across rows, as a time offset is"
        if self.line_delay_solved:
            return f"{ramp}: the rows still ramp with the line delay solved; check the lens and the stamps"
        return f"rolling shutter suspected: solve with --line-delay; {ramp}"


def image_velocity(frames: CameraFrames, track: BoardTrack) -> list[np.ndarray]:
    """Per frame (N_f, 2) px/s: each corner's board point projected through the PnP poses of the frames
    either side (one side at the ends), differenced; NaN for a frame without a pose or neighbours further
    than 1.5 median periods away (a dropped frame)."""
    out = [np.full((p.shape[0], 2), np.nan) for p in frames.object_points]
    n = track.t_s.size
    period = float(np.median(np.diff(track.t_s))) if n > 1 else 0.0
    for k, f in enumerate(track.frame):
        a, b = max(k - 1, 0), min(k + 1, n - 1)
        dt = float(track.t_s[b] - track.t_s[a])
        if not 0 < dt <= 1.5 * period * (b - a):
            continue
        X = frames.object_points[f]
        u = [
            project(
                X @ track.T_cam_w[j, :3, :3].T + track.T_cam_w[j, :3, 3],
                frames.camera_matrix,
                frames.dist_coeffs,
            )
            for j in (a, b)
        ]
        out[f] = (u[1] - u[0]) / dt
    return out


def _fit(s: np.ndarray, row: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    X = np.stack([s, s * row], axis=1)
    coef, *_ = np.linalg.lstsq(X, z, rcond=None)
    rss = float(np.sum((z - X @ coef) ** 2))
    return coef, np.linalg.inv(X.T @ X), rss / max(z.size - 2, 1)


def row_test(
    solution: ImuCameraSolution, frames: CameraFrames, track: BoardTrack | None = None
) -> RowTest | None:
    """The row test (module docstring) on the solution's inlier corners; None when the residuals cannot
    be matched to ``frames`` (another corner order) or fewer than 20 corners move."""
    res = solution.residuals
    counts = np.array([p.shape[0] for p in frames.object_points])
    use = np.flatnonzero(counts >= 4)
    velocity = image_velocity(frames, track or board_track(frames))
    u_dot = np.concatenate([velocity[f] for f in use]) if use.size else np.zeros((0, 2))
    t_corner = np.repeat(frames.t_s[use], counts[use])
    r = res["corner_px"]
    if r.shape[0] != u_dot.shape[0] or not np.allclose(t_corner, res["corner_t_s"], rtol=0, atol=1e-6):
        return None
    speed = np.linalg.norm(u_dot, axis=1)
    ok = res["corner_inlier"] & np.isfinite(speed) & (speed > MIN_SPEED_PX_S)
    if int(ok.sum()) < 20:
        return None
    s, row, t = speed[ok], res["corner_row_px"][ok], t_corner[ok]
    z = np.sum(r[ok] * u_dot[ok], axis=1) / s
    coef, inv, var = _fit(s, row, z)
    sigma_fit = float(np.sqrt(var * inv[1, 1]))
    edges = np.linspace(t.min(), t.max(), JACKKNIFE_BLOCKS + 1)
    block = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, JACKKNIFE_BLOCKS - 1)
    slopes = np.array(
        [_fit(s[block != k], row[block != k], z[block != k])[0][1] for k in range(JACKKNIFE_BLOCKS)]
    )
    sigma_jk = float(
        np.sqrt((JACKKNIFE_BLOCKS - 1) / JACKKNIFE_BLOCKS * np.sum((slopes - slopes.mean()) ** 2))
    )
    sigma = max(sigma_fit, sigma_jk)
    c_y = float(frames.camera_matrix[1, 2])
    row_edges = np.linspace(row.min(), row.max(), ROW_BINS + 1)
    which = np.clip(np.searchsorted(row_edges, row, side="right") - 1, 0, ROW_BINS - 1)
    w_sum = np.bincount(which, s**2, ROW_BINS)
    zs_sum = np.bincount(which, s * z, ROW_BINS)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = zs_sum / w_sum
        sigma_bin = np.sqrt(var / w_sum)
    slope = float(coef[1])
    score = abs(slope) / sigma if sigma > 0 else float("inf")
    return RowTest(
        slope_s_per_row=slope,
        sigma_s_per_row=sigma,
        offset_s=float(coef[0]),
        z=score,
        corners=int(ok.sum()),
        significant=bool(score > ROW_Z_SIGNIFICANT),
        line_delay_solved=solution.line_delay_s is not None,
        row_px=0.5 * (row_edges[:-1] + row_edges[1:]) + c_y,
        time_residual_s=mean,
        sigma_s=sigma_bin,
        counts=np.bincount(which, minlength=ROW_BINS),
    )


@dataclass(frozen=True)
class ReportSeries:
    """Time bins (IMU clock, s from the first IMU sample): t_s (B,); gyro_rad_s (B, 3) the mean gyro with
    the bias removed and camera_rate_rad_s (B, 3) the mean board-derived camera rate in the IMU frame at
    t_cam + td_s (NaN where a bin holds none); corner_rms_px, gyro_rms_rad_s, accel_rms_m_s2 (B,) the
    residual RMS per bin (inlier corners by their frame's time + td_s)."""

    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    camera_rate_rad_s: np.ndarray
    corner_rms_px: np.ndarray
    gyro_rms_rad_s: np.ndarray
    accel_rms_m_s2: np.ndarray


def _bin_mean(which: np.ndarray, values: np.ndarray, bins: int) -> np.ndarray:
    n = np.bincount(which, minlength=bins).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.stack([np.bincount(which, v, bins) / n for v in np.atleast_2d(values.T)], axis=1)


def report_series(
    solution: ImuCameraSolution,
    imu: ImuSamples,
    frames: CameraFrames,
    track: BoardTrack | None = None,
    bins: int | None = None,
) -> ReportSeries:
    """The report's time series (``ReportSeries``), binned over the solve's IMU span: ``bins`` or bins of
    ``SERIES_MIN_BIN_S``, at most ``SERIES_MAX_BINS``."""
    res = solution.residuals
    t0 = float(imu.t_s[0])
    t_imu = res["imu_t_s"]
    span = float(t_imu.max() - t_imu.min())
    bins = bins or int(min(SERIES_MAX_BINS, max(1, np.ceil(span / SERIES_MIN_BIN_S))))
    edges = np.linspace(t_imu.min(), t_imu.max(), bins + 1)

    def which(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        inside = (t >= edges[0]) & (t <= edges[-1])
        return np.clip(np.searchsorted(edges, t[inside], side="right") - 1, 0, bins - 1), inside

    k, inside = which(imu.t_s)
    gyro = _bin_mean(k, imu.gyro_rad_s[inside] - solution.gyro_bias_rad_s, bins)
    t_mid, _, w_cam = camera_rates(track or board_track(frames))
    k, inside = which(t_mid + solution.td_s)
    cam = _bin_mean(k, w_cam[inside] @ solution.T_imu_cam[:3, :3].T, bins)
    k, _ = which(t_imu)
    gyro_rms = np.sqrt(_bin_mean(k, np.sum(res["gyro_rad_s"] ** 2, axis=1), bins)[:, 0])
    accel_rms = np.sqrt(_bin_mean(k, np.sum(res["accel_m_s2"] ** 2, axis=1), bins)[:, 0])
    inl = res["corner_inlier"]
    k, inside = which(res["corner_t_s"][inl] + solution.td_s)
    corner_rms = np.sqrt(_bin_mean(k, np.sum(res["corner_px"][inl][inside] ** 2, axis=1), bins)[:, 0])
    return ReportSeries(
        t_s=0.5 * (edges[:-1] + edges[1:]) - t0,
        gyro_rad_s=gyro,
        camera_rate_rad_s=cam,
        corner_rms_px=corner_rms,
        gyro_rms_rad_s=gyro_rms,
        accel_rms_m_s2=accel_rms,
    )
