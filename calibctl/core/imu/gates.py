"""Camera-IMU gates (seed chapters 2-3), each a ``core.gate.GateResult`` with the next action in its hint.

- ``rotational_excitation``: the smallest singular value of the stacked (R_k - I) over the camera's
  relative rotations between poses a span apart, per pair of motions (sigma_min * sqrt(2 / m) for m
  motions: two perpendicular turns of theta give 2 sin(theta / 2)), the best of ``MOTION_SPANS_S``.
  Chapter 2: below ~0.5 (under ~30 deg about two axes) do not trust the translation.
- ``td_observability``: the median image speed of the corners (px/s); chapter 3's production gate,
  20 px/s (u-dot = 0 makes td unobservable). The speed's spread over time and td's CRLB ride along.
- ``td_rotation_correlation``: the multiple correlation of td with the three rotation states in the
  solution's covariance. Smooth constant-rate motion makes the (td, yaw) plane rank-deficient (chapter
  3): the solver converges anyway, so a high correlation means hold one of the two or refuse.
- ``td_sigma``: td's one-sigma against ``MAX_SIGMA_TD_MS``.
- ``saturation``: the share of IMU samples at full scale or pinned at an axis' extreme.
- ``imu_gaps`` / ``dropped_frames``: the longest IMU gap in sample periods; the share of camera frames
  missing from an even stream.
- ``imu_model_observability``: with an IMU model beyond ``calibrated``, the smallest eigenvalue of the
  data's prior-scaled information on its states, at least ``intrinsics.MIN_INFORMATION``.
- ``board_scale``: the board's true size over its registered size as the accelerometer measures it
  (``metric.board_scale``), off 1 by at most ``SCALE_SIGMAS`` sigma or ``MIN_SCALE_ERROR``.
- ``camera_fit``: the corners' F ratio about the IMU's trajectory against their per-frame PnP fit
  (``metric.camera_fit``), at most ``MAX_CAMERA_FIT_F`` or an excess under ``MIN_CAMERA_EXCESS_PX``:
  wrong intrinsics cannot follow the IMU's turns.
- ``rig_pose``: a camera a joint solve held through the rig's pose to the first camera: its corner
  RMS over its per-frame PnP RMS (``pnp_rms_px``), at most ``MAX_RIG_POSE_RATIO``.
"""

from __future__ import annotations

import numpy as np

from calibctl.core.gate import GateResult
from calibctl.core.imu import intrinsics, metric
from calibctl.core.imu.plain import BoardTrack
from calibctl.core.imu.samples import CameraFrames, ImuSamples, median_period_s

MOTION_SPANS_S = (0.5, 1.0, 2.0, 3.0)
MIN_EXCITATION = 0.5
MIN_IMAGE_SPEED_PX_S = 20.0
MAX_TD_ROTATION_CORRELATION = 0.95
MAX_SIGMA_TD_MS = 0.5
MAX_SATURATED_SHARE = 0.001
MAX_IMU_GAP_PERIODS = 5.0
MAX_DROPPED_SHARE = 0.05
MAX_RIG_POSE_RATIO = 2.0  # a held camera's corner RMS over its per-frame PnP RMS
# The board's scale is refused off 1 by more than both SCALE_SIGMAS sigma and MIN_SCALE_ERROR: a few
# percent is what an accelerometer's own scale error and a print's shrinkage leave (EuRoC: 0.990).
SCALE_SIGMAS = 3.0
MIN_SCALE_ERROR = 0.03
MAX_CAMERA_FIT_F = 2.0  # the corners' variance excess over their per-frame PnP fit, per pose state
# ... refused only with at least this much excess RMS: the trajectory model's own floor on noise-free
# rendered images is 0.064 px, a 6 % focal error's 0.11-0.15 px (benchmarks/results/imu.md).
MIN_CAMERA_EXCESS_PX = 0.08


def _verdict(
    gate: str,
    value: float,
    threshold: float,
    passed: bool,
    message: str,
    reason: str,
    hint: str,
    detail: dict[str, float | int | str | list[str]] | None = None,
) -> GateResult:
    """A GateResult whose reason and hint are kept only when it failed."""
    return GateResult(
        gate=gate,
        passed=passed,
        value=value,
        threshold=threshold,
        message=message,
        reason=None if passed else reason,
        hint=None if passed else hint,
        detail=detail or {},
    )


def _excitation(track: BoardTrack, span_s: float) -> tuple[float, int]:
    R = track.T_w_cam[:, :3, :3]
    later = np.searchsorted(track.t_s, track.t_s + span_s)
    ok = later < track.t_s.size
    first, second = np.flatnonzero(ok), later[ok]
    if first.size < 2:
        return 0.0, int(first.size)
    rel = np.einsum("nji,njk->nik", R[first], R[second])
    stacked = (rel - np.eye(3)).reshape(-1, 3)
    return float(np.linalg.svd(stacked, compute_uv=False)[-1] * np.sqrt(2.0 / first.size)), int(first.size)


def rotational_excitation(track: BoardTrack, spans_s: tuple[float, ...] = MOTION_SPANS_S) -> GateResult:
    """The best of the spans: a recording that turns slowly about one axis and fast about another is
    judged on the span that shows both turns."""
    value, motions, span = max((*_excitation(track, s), s) for s in spans_s)
    passed = value >= MIN_EXCITATION
    return _verdict(
        "rotational_excitation",
        value,
        MIN_EXCITATION,
        passed,
        f"rotational excitation {value:.3f} per pair of {span:g} s motions (at least "
        f"{MIN_EXCITATION} = about 30 deg about two axes)",
        "rotation_starved",
        "the recording turns about too few axes or too little, so the lever arm (translation) is "
        "not pinned: record again turning the sensor at least 30 deg about each of its three axes, with "
        "reversals (a figure-of-eight with wrist turns)",
        {"motions": motions, "span_s": span},
    )


def image_velocities(frames: CameraFrames, max_gap_factor: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """Per pair of consecutive frames: the median corner speed (px/s) and the mean corner velocity
    (2,) px/s; corners matched by their board point. Returns ((m,), (m, 2))."""
    period = median_period_s(frames.t_s)
    speeds, means = [], []
    for f in range(len(frames.t_s) - 1):
        dt = frames.t_s[f + 1] - frames.t_s[f]
        a_obj, b_obj = frames.object_points[f], frames.object_points[f + 1]
        if dt > max_gap_factor * period or a_obj.shape[0] == 0 or b_obj.shape[0] == 0:
            continue
        keys_a = {tuple(p): i for i, p in enumerate(np.round(a_obj, 6))}
        pairs = [(keys_a[tuple(p)], j) for j, p in enumerate(np.round(b_obj, 6)) if tuple(p) in keys_a]
        if not pairs:
            continue
        ia, ib = np.array(pairs).T
        v = (frames.image_points[f + 1][ib] - frames.image_points[f][ia]) / dt
        speeds.append(float(np.median(np.linalg.norm(v, axis=1))))
        means.append(v.mean(axis=0))
    return np.array(speeds), np.array(means).reshape(-1, 2)


def td_observability(frames: CameraFrames, td_crlb_ms: float | None = None) -> GateResult:
    speeds, means = image_velocities(frames)
    value = float(np.median(speeds)) if speeds.size else 0.0
    spread = float(np.sqrt(np.sum(np.var(means, axis=0)))) if means.shape[0] > 1 else 0.0
    passed = value >= MIN_IMAGE_SPEED_PX_S
    detail: dict[str, float | int | str | list[str]] = {
        "velocity_spread_px_s": spread,
        "pairs": int(speeds.size),
    }
    if td_crlb_ms is not None:
        detail["td_crlb_ms"] = td_crlb_ms
    return _verdict(
        "td_observability",
        value,
        MIN_IMAGE_SPEED_PX_S,
        passed,
        f"median corner speed {value:.1f} px/s (at least {MIN_IMAGE_SPEED_PX_S:g}), spread over "
        f"time {spread:.1f} px/s",
        "image_static",
        "the board barely moves in the image, so td cannot be seen (u-dot = 0): record again "
        "turning the sensor so the board sweeps across the image, with reversals",
        detail,
    )


def td_rotation_correlation(covariance_7: np.ndarray, td_held: bool) -> GateResult:
    """Multiple correlation of td with (rot_x, rot_y, rot_z) from the (7, 7) covariance."""
    if td_held:
        return GateResult(
            gate="td_rotation_correlation",
            passed=True,
            value=0.0,
            threshold=MAX_TD_ROTATION_CORRELATION,
            message="td held, not estimated: no (td, rotation) correlation",
            detail={"held": "td"},
        )
    S_rr, s_rt, s_tt = covariance_7[:3, :3], covariance_7[:3, 6], covariance_7[6, 6]
    r2 = float(s_rt @ np.linalg.solve(S_rr, s_rt) / s_tt) if s_tt > 0 else 1.0
    value = float(np.sqrt(np.clip(r2, 0.0, 1.0)))
    passed = value <= MAX_TD_ROTATION_CORRELATION
    return _verdict(
        "td_rotation_correlation",
        value,
        MAX_TD_ROTATION_CORRELATION,
        passed,
        f"td correlates with the extrinsic rotation at {value:.3f} (at most "
        f"{MAX_TD_ROTATION_CORRELATION}); sigma td {1e3 * np.sqrt(max(s_tt, 0.0)):.3f} ms",
        "td_rotation_degenerate",
        "the motion rotates at a near-constant rate, so a time offset and an extrinsic rotation "
        "explain the data equally (seed chapter 3): record again with rate reversals on every axis, or "
        "hold td at a known value (a hardware-triggered rig: 0) and estimate the extrinsic alone",
    )


def td_sigma(sigma_td_ms: float, td_held: bool) -> GateResult:
    """td's one-sigma: a near-constant rate leaves it large even when no rotation state takes the blame
    (the rotation about the one turning axis is itself unpinned, so the correlation reads low)."""
    value = 0.0 if td_held else sigma_td_ms
    passed = value <= MAX_SIGMA_TD_MS
    return _verdict(
        "td_sigma",
        value,
        MAX_SIGMA_TD_MS,
        passed,
        "td held, not estimated" if td_held else f"sigma td {value:.3f} ms (at most {MAX_SIGMA_TD_MS} ms)",
        "td_unpinned",
        "the motion does not pin td: record again with rate reversals on every axis, or hold td at a "
        "known value (a hardware-triggered rig: 0)",
    )


def saturation(imu: ImuSamples) -> GateResult:
    gyro, accel = imu.saturated()
    both = gyro | accel
    value = float(both.mean())
    passed = value <= MAX_SATURATED_SHARE
    return _verdict(
        "saturation",
        value,
        MAX_SATURATED_SHARE,
        passed,
        f"{int(gyro.sum())} gyro and {int(accel.sum())} accelerometer samples saturated "
        f"({100 * value:.2f} % of {both.size})",
        "imu_saturated",
        "the motion exceeded the IMU's range: record again moving less violently, or set a larger "
        "full-scale range on the IMU",
        {"gyro_samples": int(gyro.sum()), "accel_samples": int(accel.sum())},
    )


def imu_gaps(imu: ImuSamples) -> GateResult:
    period = median_period_s(imu.t_s)
    steps = np.diff(imu.t_s)
    value = float(steps.max() / period)
    passed = value <= MAX_IMU_GAP_PERIODS
    at = float(imu.t_s[int(np.argmax(steps))])
    return _verdict(
        "imu_gaps",
        value,
        MAX_IMU_GAP_PERIODS,
        passed,
        f"longest IMU gap {1e3 * steps.max():.1f} ms = {value:.1f} sample periods (at {at:.3f} s)",
        "imu_gap",
        "the IMU log drops samples: check the driver's queue and the logger's load, then record "
        "again (an integrated gap bends the trajectory)",
        {"at_s": at},
    )


def dropped_frames(frames: CameraFrames) -> GateResult:
    period = median_period_s(frames.t_s)
    missing = int(np.sum(np.maximum(np.round(np.diff(frames.t_s) / period) - 1, 0)))
    value = missing / (frames.t_s.size + missing)
    passed = value <= MAX_DROPPED_SHARE
    return _verdict(
        "dropped_frames",
        value,
        MAX_DROPPED_SHARE,
        passed,
        f"{missing} camera frames missing from an even {1 / period:.1f} Hz stream ({100 * value:.1f} %)",
        "frames_dropped",
        "the camera stream drops frames: lower the frame rate or the resolution, or record to a "
        "faster disk, then record again",
        {"missing": missing},
    )


def rate_variation_refused(message: str) -> GateResult:
    """The rate cross-correlation could not pin td before any solve (its message says why)."""
    return GateResult(
        gate="td_rotation_correlation",
        passed=False,
        value=1.0,
        threshold=MAX_TD_ROTATION_CORRELATION,
        message=message,
        reason="td_rotation_degenerate",
        hint="the gyro rate hardly changes, so td cannot be told from an extrinsic rotation (seed "
        "chapter 3): record again with rate reversals on every axis, or hold td at a known value (a "
        "hardware-triggered rig: 0) and estimate the extrinsic alone",
    )


def pnp_rms_px(frames: CameraFrames, track: BoardTrack) -> float:
    """The corners' 2-D RMS about each frame's own PnP pose: the floor any trajectory fit is judged by."""
    return float(np.sqrt(np.mean(np.sum(metric.pnp_residuals(frames, track) ** 2, axis=1))))


def rig_pose(corner_rms_px: float, pnp_rms_px: float) -> GateResult:
    """A camera held through the rig's pose to the first camera: its corners about the joint solve
    against their own per-frame PnP fit. A rig pose the corners contradict (re-mounted camera, another
    rig version) leaves them far off both cameras' shared trajectory."""
    ratio = corner_rms_px / max(pnp_rms_px, 1e-9)
    return _verdict(
        "rig_pose",
        ratio,
        MAX_RIG_POSE_RATIO,
        ratio <= MAX_RIG_POSE_RATIO,
        f"held through the rig's pose to the first camera: corner RMS {corner_rms_px:.3f} px against "
        f"{pnp_rms_px:.3f} px about its own per-frame poses ({ratio:.2f}x, at most {MAX_RIG_POSE_RATIO:g}x)",
        "rig_pose_contradicted",
        "the rig's pose between the cameras does not fit these corners: re-solve the rig, or solve the "
        "cameras without --rig (each its own T_imu_cam)",
    )


def imu_model_observability(model: str, min_information: float) -> GateResult:
    """The IMU model's states (``core.imu.intrinsics``): the smallest eigenvalue of the data's
    information on their block, everything else integrated out, scaled by their prior sigmas. Under
    ``MIN_INFORMATION`` the prior, not the recording, holds some direction of scale, misalignment or
    g-sensitivity, and the extrinsic rotation (pinned through the accelerometer frame) is not trusted."""
    value = float(min_information)
    threshold = intrinsics.MIN_INFORMATION
    passed = bool(np.isfinite(value) and value >= threshold)
    return _verdict(
        "imu_model_observability",
        value,
        threshold,
        passed,
        f"IMU model {model}: in its least-seen direction the data alone give "
        f"{1.0 / np.sqrt(max(value, 1e-12)):.2g} of the prior's sigma (prior-scaled information "
        f"{value:.1f}, at least {threshold:g})",
        "imu_model_unobservable",
        f"the motion cannot pin the {model} IMU model's states: record longer with turns about every axis "
        "and tilts through gravity, or solve with --imu-model calibrated",
    )


def board_scale(scale: metric.BoardScale, square_mm: float | None = None) -> GateResult:
    """The IMU as the board's metric gauge: a board registered at the wrong size (another revision, a
    print scaled to fit the page) scales every camera position, and the lever arm takes the blame."""
    error = abs(scale.scale - 1.0)
    limit = max(SCALE_SIGMAS * scale.sigma, MIN_SCALE_ERROR)
    sizes = (
        f" (its square or tag edge {scale.scale * square_mm:.1f} +/- {scale.sigma * square_mm:.1f} mm, not "
        f"{square_mm:.1f} mm)"
        if square_mm is not None
        else ""
    )
    return _verdict(
        "board_scale",
        scale.scale,
        limit,
        error <= limit,
        f"the accelerometer measures the board at {scale.scale:.3f} +/- {scale.sigma:.3f} times its "
        f"registered size{sizes}; refused off 1 by more than {SCALE_SIGMAS:g} sigma and "
        f"{100 * MIN_SCALE_ERROR:g} %",
        "board_scale_contradicted",
        "the board filmed is not the size registered: measure its squares (calipers) and register it "
        "(`calibctl board add NAME --square-mm ... --uncertainty-mm ...`), or pass the board that was "
        "filmed, then solve again",
        {"sigma": scale.sigma, "inflation": scale.inflation},
    )


def camera_fit(fit: metric.CameraFit) -> GateResult:
    """Wrong intrinsics (another camera's, a focal length a few percent off) still let each frame find
    a pose, but not one IMU trajectory whose turns the gyro measures: the corners' excess over their
    per-frame fit, per pose state the fit spent, is about 1 with the right camera model."""
    value = fit.f_ratio
    small = fit.excess_px < MIN_CAMERA_EXCESS_PX
    passed = bool(np.isfinite(value) and (value <= MAX_CAMERA_FIT_F or small))
    return _verdict(
        "camera_fit",
        value,
        MAX_CAMERA_FIT_F,
        passed,
        ("" if passed else "the camera's intrinsics do not fit these images: ")
        + f"corners {fit.joint_sigma_px:.3f} px about the IMU's trajectory against {fit.pnp_sigma_px:.3f} "
        f"px about their own per-frame poses, F {value:.2f} (at most {MAX_CAMERA_FIT_F:g}), "
        f"{fit.excess_px:.3f} px beyond what those poses explain (refused from {MIN_CAMERA_EXCESS_PX:g} px)",
        "intrinsics_contradicted",
        "check that the recording is this camera's and that its active calibration is this lens' "
        "(calibrate the camera again, or roll back to the version that fits), then solve again; a "
        "rolling-shutter camera solved without --line-delay reads the same",
        {
            "joint_sigma_px": fit.joint_sigma_px,
            "pnp_sigma_px": fit.pnp_sigma_px,
            "pose_states": fit.pose_states,
            "excess_px": fit.excess_px,
        },
    )
