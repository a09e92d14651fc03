"""Observability gates and screens for hand-eye data (seed chapter 2), checked before any number.

- rotation: R_X is pinned only by two rotations about non-parallel axes (M = sum a_i b_i^T of
  rank 2; the det guard supplies the third bit). Value: s2, the second singular value of the
  stacked axis-angle vectors of A, in degrees: how much the motions rotate about a second axis
  (two motions of 30 deg about perpendicular axes: 30; a corridor's noise-level wobble: ~1).
- lever-arm: the translation needs sigma_min of the stacked (R_A - I) >= 0.5 (about 30 deg of
  excitation): an error d in a motion translation becomes d / sigma_min in the lever arm.
- time-alignment: conjugation keeps the rotation angle, so |angle(A_i)| = |angle(B_i)| for a
  synchronised pair; a mismatch is a time offset (failure mode B) or a wrong pairing, and
  would otherwise be absorbed into R_X. Motions over the limit are named.

After the solve, one more gate before the number is reported:

- consistency: the rotation residual RMS (per component) of the refined X. Rigidly attached,
  synchronised sensors leave only their noise (0.08 deg on the real opencv-left-right pair);
  data that no single X explains (a robot arm solved eye-in-hand instead of eye-to-hand, poses
  given as gripper->base, mismatched rows) leave degrees, which an observability gate cannot see
  when the angles of A and B still agree.

- translation-scale: the rotation residual cannot see a unit error in the translations, and on a
  log dominated by pure rotation (an arm turning about its tool point moves it micrometres) the
  translation norms cannot either (handeye_io.check_units). The translation half
  ``(R_A - I) t_X = R_X t_B - t_A`` can: with R_X fixed it is linear in t_X and a scale s on a's
  translations, and rigid sensors in one unit give s = 1. Measured (2026-11-26, real RWHE-Calib KUKA
  logs, camera poses from the board): s = 0.998 (kuka_1) and 1.058 (kuka_2: the 15 mm board against
  the robot's metres, 6 % apart); seeded pose/motion logs with 2-20 mm noise within 2 % of 1. The
  same logs with a's translations in mm: s = 0.000998 / 0.001058 (lever arms of 1298 m / 406 m and
  translation residuals of 220 m / 7.5 m accepted before this gate); in cm 0.0100 / 0.0106, in
  inches 0.025 / 0.027, in feet 0.304 / 0.323. So a disagreement beyond 1.25x is refused; a factor
  near 1000, 100, 39.4 or 3.28 is named as the unit. Below that, a scale that differs from 1 by more than
  its own 3 sigma AND the station's tolerance (``translation_scale_tolerance``, 1 % by default: the
  distance gauge's limits, 0.99-1.01) is a metric-gauge verdict (seed chapter 0): one sensor's metres are
  not the other's, for a camera through the board's square size (23 mm typed for 25 mm: s = 0.920 on a
  noise-free rendered arm log, 0.920 +/- 0.0007 on a second one, 120 sigma from 1, accepted before this rule).
  kuka_2's 1.058 (the 15 mm board against the robot's metres) is refused by it unless its sigma exceeds 2 %.

Outlier motions (per-motion residual far above the robust scale of all motions) are named, not dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibctl.core.extrinsics.handeye import Motions, translation_scale
from calibctl.core.extrinsics.handeye_refine import HandEyeFit
from calibctl.core.gate import GateResult
from calibctl.errors import named_list

LEVER_ARM_SIGMA_MIN = 0.5
SECOND_AXIS_MIN_DEG = 10.0
ANGLE_MISMATCH_MAX_DEG = 1.0
ROTATION_RESIDUAL_MAX_DEG = 1.0
MISMATCH_FRACTION_MAX = 0.1  # more than one motion in ten: a clock problem, not a bad sample
OUTLIER_FACTOR = 4.0  # |r| / robust sigma: the 99.9 % point of a 3-D Gaussian's norm is 4.03 sigma
CHI3_MEDIAN = 1.5382  # median of the norm of a 3-D standard Gaussian
MIN_MOTIONS_FOR_OUTLIERS = 5
MAX_NAMED = 5
TRANSLATION_SCALE_MAX = 1.25  # real logs 1.00-1.06, a wrong unit >= 3.1 (feet); see the module docstring
SCALE_DETERMINED_SIGMAS = 3.0  # |s - 1| within 3 sigma_s: the motions do not pin the scale, nothing to judge
TRANSLATION_SCALE_TOLERANCE = 0.01  # the distance gauge's limits (workflows.camera.distance_gauge, 0.99-1.01)
UNIT_FACTORS = (("millimetres", 1000.0), ("centimetres", 100.0), ("inches", 1 / 0.0254), ("feet", 1 / 0.3048))
UNIT_FACTOR_TOL = (
    0.15  # a board's square size or an odometry's scale can add a few per cent to the unit's factor
)


@dataclass(frozen=True)
class HandEyeThresholds:
    lever_arm_sigma_min: float = LEVER_ARM_SIGMA_MIN
    second_axis_min_deg: float = SECOND_AXIS_MIN_DEG
    angle_mismatch_max_deg: float = ANGLE_MISMATCH_MAX_DEG
    mismatch_fraction_max: float = MISMATCH_FRACTION_MAX
    rotation_residual_max_deg: float = ROTATION_RESIDUAL_MAX_DEG
    translation_scale_tolerance: float = TRANSLATION_SCALE_TOLERANCE

    def __post_init__(self) -> None:
        positive = (
            self.lever_arm_sigma_min,
            self.second_axis_min_deg,
            self.angle_mismatch_max_deg,
            self.rotation_residual_max_deg,
            self.translation_scale_tolerance,
        )
        if not all(v > 0 for v in positive):
            raise ValueError("hand-eye thresholds must be positive")
        if not 0 <= self.mismatch_fraction_max < 1:
            raise ValueError(f"mismatch_fraction_max must be in [0, 1), got {self.mismatch_fraction_max}")


def equivalent_rotation_deg(sigma_min: float) -> float:
    """The single rotation theta with 2 sin(theta/2) = sigma_min, degrees (180 when sigma_min >= 2)."""
    return math.degrees(2.0 * math.asin(min(1.0, sigma_min / 2.0)))


def lever_arm_conditioning(R_A: np.ndarray) -> tuple[float, np.ndarray]:
    """sigma_min of the stacked (R_A - I) of (n, 3, 3) rotations, and the (3,) direction it belongs to."""
    _, s, Vt = np.linalg.svd((np.asarray(R_A, np.float64) - np.eye(3)).reshape(-1, 3))
    return float(s[-1]), Vt[-1]


def rotation_excitation_deg(rotvec_A_rad: np.ndarray) -> tuple[float, float]:
    """(s2 in degrees, axis spread 2 atan(s2/s1) in degrees) of the (n, 3) stacked axis-angle vectors.

    s2 is the root-sum-square rotation about the best second axis; the spread is the angle between
    the axes of two equal rotations (0 for one axis or none).
    """
    s = np.linalg.svd(np.asarray(rotvec_A_rad, np.float64).reshape(-1, 3), compute_uv=False)
    spread = 0.0 if s[0] <= 1e-12 else math.degrees(2.0 * math.atan2(s[1], s[0]))
    return math.degrees(s[1]), spread


def angle_mismatch_deg(motions: Motions) -> np.ndarray:
    """(n,) |angle(A_i)| - |angle(B_i)| in degrees (signed)."""
    return np.degrees(
        np.linalg.norm(motions.rotvec_A_rad, axis=1) - np.linalg.norm(motions.rotvec_B_rad, axis=1)
    )


def rotation_gate(motions: Motions, th: HandEyeThresholds) -> GateResult:
    second, spread = rotation_excitation_deg(motions.rotvec_A_rad)
    ok = second >= th.second_axis_min_deg
    message = (
        f"{second:.1f} deg of rotation about a second axis (needs {th.second_axis_min_deg:g}; "
        f"axes spread {spread:.0f} deg)"
    )
    detail: dict[str, float | int | str | list[str]] = {"axis_spread_deg": round(spread, 3)}
    if ok:
        return GateResult("rotation", True, second, th.second_axis_min_deg, message, detail=detail)
    return GateResult(
        "rotation",
        False,
        second,
        th.second_axis_min_deg,
        f"rotation unobservable: only {message}; the motions turn about one axis (or hardly at all)",
        "rotation.one_axis",
        f"rotate at least {th.second_axis_min_deg:g} deg about a second, non-parallel axis",
        detail,
    )


def lever_arm_gate(motions: Motions, th: HandEyeThresholds) -> GateResult:
    sigma_min, weakest = lever_arm_conditioning(motions.R_A)
    ok = sigma_min >= th.lever_arm_sigma_min
    about = equivalent_rotation_deg(sigma_min)
    needed = 5.0 * math.ceil(equivalent_rotation_deg(th.lever_arm_sigma_min) / 5.0 - 1e-9)
    hint = f"rotate at least {needed:.0f} deg about two non-parallel axes"
    detail: dict[str, float | int | str | list[str]] = {
        "weakest_direction_a": [f"{v:+.3f}" for v in weakest],
        "equivalent_rotation_deg": round(about, 3),
    }
    if ok:
        return GateResult(
            "lever-arm",
            True,
            sigma_min,
            th.lever_arm_sigma_min,
            f"sigma_min of stacked (R_A - I) {sigma_min:.3f} (needs {th.lever_arm_sigma_min:g})",
            detail=detail,
        )
    return GateResult(
        "lever-arm",
        False,
        sigma_min,
        th.lever_arm_sigma_min,
        f"lever arm unobservable: sigma_min {sigma_min:.3f} (about {about:.{0 if about >= 1.5 else 1}f} "
        "deg of "
        f"rotation); {hint}",
        "lever_arm.unobservable",
        hint,
        detail,
    )


STATIC_POSE_HINT = (
    "the poses were held still at each photo, so no time offset explains it: check that each row "
    "pairs a photo with the pose it was taken at (a pose file shifted or reordered against the "
    "images), the pose convention (base->gripper, not gripper->base) and the board detections of the "
    "mismatched motions"
)


def time_alignment_gate(motions: Motions, th: HandEyeThresholds, static_poses: bool = False) -> GateResult:
    """Both sensors turn by the same angle in every motion. The hint names the cause by the log: a time offset
    for a log in time; for ``static_poses`` (a robot arm that stops for each photo) a time offset cannot turn
    one sensor more than the other, so the pairing and the convention are."""
    mismatch = angle_mismatch_deg(motions)
    bad = np.flatnonzero(np.abs(mismatch) > th.angle_mismatch_max_deg)
    fraction = bad.size / max(motions.n, 1)
    ok = fraction <= th.mismatch_fraction_max
    worst = int(np.argmax(np.abs(mismatch)))
    message = (
        f"{bad.size} of {motions.n} motions turn by a different angle in a and b "
        f"(> {th.angle_mismatch_max_deg:g} deg; worst {mismatch[worst]:+.2f} deg at {motions.labels[worst]})"
    )
    detail: dict[str, float | int | str | list[str]] = {
        "mismatched_motions": [motions.labels[i] for i in bad]
    }
    if ok:
        return GateResult("time-alignment", True, fraction, th.mismatch_fraction_max, message, detail=detail)
    return GateResult(
        "time-alignment",
        False,
        fraction,
        th.mismatch_fraction_max,
        f"time alignment: {message}, e.g. {named_list([motions.labels[i] for i in bad], MAX_NAMED)}",
        "time_alignment.angle_mismatch",
        STATIC_POSE_HINT
        if static_poses
        else "a time offset between the sensors masquerades as an extrinsic error: estimate it "
        "(calibctl timeoffset), re-synchronise the log and solve again",
        detail,
    )


def evaluate_handeye_gates(
    motions: Motions, th: HandEyeThresholds | None = None, static_poses: bool = False
) -> tuple[GateResult, ...]:
    th = th or HandEyeThresholds()
    return (
        rotation_gate(motions, th),
        lever_arm_gate(motions, th),
        time_alignment_gate(motions, th, static_poses),
    )


def consistency_gate(fit: HandEyeFit, th: HandEyeThresholds) -> GateResult:
    """After the solve: does one rigid X explain the rotations? (see the module docstring)"""
    rms_deg = math.degrees(fit.sigma_residual_rotation_rad)
    ok = rms_deg <= th.rotation_residual_max_deg
    message = f"rotation residual RMS {rms_deg:.3f} deg per component (max {th.rotation_residual_max_deg:g})"
    if ok:
        return GateResult("consistency", True, rms_deg, th.rotation_residual_max_deg, message)
    return GateResult(
        "consistency",
        False,
        rms_deg,
        th.rotation_residual_max_deg,
        f"motions inconsistent with one rigid transform: {message}",
        "consistency.rotation_residual",
        "check the pose conventions (a robot arm: base->gripper poses, --eye-in-hand vs "
        "--eye-to-hand), that each row pairs the same instant, and the outlier motions",
    )


def _unit_named(factor: float) -> str | None:
    for unit, expected in UNIT_FACTORS:
        if abs(factor / expected - 1.0) <= UNIT_FACTOR_TOL:
            return unit
    return None


def translation_scale_gate(
    motions: Motions,
    fit: HandEyeFit,
    names: tuple[str, str] = ("a", "b"),
    tolerance: float = TRANSLATION_SCALE_TOLERANCE,
) -> GateResult:
    """After the solve (and a passed consistency gate): are both sensors' translations in one unit and one
    metric scale?

    Value: the disagreement factor max(|s|, 1/|s|) of the scale s on a's translations (see the module
    docstring); a negative s (translations pointing against each other) fails whatever its size. It passes
    while |s - 1| is within 3 sigma or within ``tolerance`` (the station's, a fraction).
    """
    s, sigma = translation_scale(motions, fit.T_a_b[:3, :3])
    size = max(abs(s), 1e-300)
    factor = max(size, 1.0 / size)
    determined = abs(s - 1.0) > SCALE_DETERMINED_SIGMAS * sigma
    detail: dict[str, float | int | str | list[str]] = {
        "scale_a": round(s, 9),
        "sigma_scale_a": round(sigma, 9) if math.isfinite(sigma) else "undetermined",
        "tolerance": tolerance,
    }
    message = (
        f"{names[0]}'s translations fit {names[1]}'s at scale {s:.4g} (+/- {sigma:.2g}; "
        f"tolerance {100 * tolerance:g} %)"
    )
    if not determined or (s > 0 and abs(s - 1.0) <= tolerance):
        return GateResult("translation-scale", True, factor, 1.0 + tolerance, message, detail=detail)
    big = names[0] if abs(s) < 1 else names[1]
    unit = _unit_named(factor) if s > 0 else None
    if unit is not None:
        return GateResult(
            "translation-scale",
            False,
            factor,
            1.0 + tolerance,
            f"translation units disagree: {message}: {big}'s translations look like {unit}, not metres",
            "translation_scale.unit",
            f"convert {big}'s translations to metres",
            detail,
        )
    if s > 0 and factor <= TRANSLATION_SCALE_MAX:
        n_sigma = abs(s - 1.0) / sigma if sigma > 0 else math.inf
        return GateResult(
            "translation-scale",
            False,
            factor,
            1.0 + tolerance,
            f"the metric gauge disagrees: {message}, {n_sigma:.0f} sigma from 1: one sensor's metres are "
            f"not the other's (seed chapter 0: a camera's scale is its board's square size; 23 mm "
            f"typed for 25 mm gives 0.920)",
            "translation_scale.metric_gauge",
            "gauge the metric scale: measure the board's squares (calipers) and register them "
            "(`calibctl board add`), check the camera with `calibctl check --reference-distance`, "
            "then recalibrate and solve again; a robot's or a LiDAR's translations are metric by "
            "construction",
            detail,
        )
    return GateResult(
        "translation-scale",
        False,
        factor,
        1.0 + tolerance,
        f"translation scales disagree: {message}",
        "translation_scale.mismatch",
        "both logs must be metric and in metres: check the board's square size (it sets a camera's "
        "scale), that neither log is scale-free (monocular visual odometry) and the pose conventions",
        detail,
    )


def outlier_motions(fit: HandEyeFit) -> np.ndarray:
    """(n,) bool: a motion whose rotation or translation residual exceeds OUTLIER_FACTOR robust sigmas.

    The robust sigma is median |r| / 1.538 (the median norm of a 3-D Gaussian), so one bad motion
    cannot hide itself by inflating the scale. Fewer than 5 motions: nothing is named.
    """
    flags = np.zeros(fit.residual_rotation_rad.shape[0], dtype=bool)
    if flags.size < MIN_MOTIONS_FOR_OUTLIERS:
        return flags
    for residual in (fit.residual_rotation_rad, fit.residual_translation_m):
        norm = np.linalg.norm(residual, axis=1)
        scale = max(float(np.median(norm)) / CHI3_MEDIAN, 1e-12)
        flags |= norm > OUTLIER_FACTOR * scale
    return flags
