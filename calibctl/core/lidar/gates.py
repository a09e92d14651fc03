"""Gates before and after the camera-LiDAR solve, each saying what the operator should do next.

Before: ``lidar-poses`` (enough accepted poses), ``lidar-observability`` (the stacked board normals in
the LiDAR frame, N (n x 3): its smallest singular value over sqrt(n) is the RMS spread of the normals
along the weakest direction; boards that all face one way leave the translation across that shared
normal and the rotation about it to the board outline alone - the seed's rank argument), and
``lidar-range-spread`` (near and far boards separate a range offset from the translation).
After: ``lidar-plane-rms`` (point-to-plane, mm), ``lidar-dimension`` (mean board dimension error, mm),
``lidar-held-out`` (k-fold point-to-plane RMS against the in-sample RMS).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from calibctl.core.gate import GateResult

MIN_POSES = 6
MIN_NORMAL_SPREAD = 0.08  # sigma_min(N) / sqrt(n): ~5 degrees RMS of tilt along the weakest direction
MIN_RANGE_SPREAD_M = 0.5
MAX_PLANE_RMS_MM = 25.0  # a VLP-16 is +/- 30 mm per return
MAX_DIMENSION_ERROR_MM = 30.0  # acfr's README: board dimension errors under 30 mm are acceptable
MAX_HELD_OUT_RATIO = 1.5
_AXES = ("x", "y", "z")


def _direction(v: np.ndarray) -> str:
    k = int(np.argmax(np.abs(v)))
    return f"LiDAR {'+' if v[k] > 0 else '-'}{_AXES[k]} ({v[0]:+.2f}, {v[1]:+.2f}, {v[2]:+.2f})"


def pose_count_gate(n_accepted: int, n_scans: int, min_poses: int = MIN_POSES) -> GateResult:
    ok = n_accepted >= min_poses
    return GateResult(
        "lidar-poses",
        ok,
        float(n_accepted),
        float(min_poses),
        f"{n_accepted} of {n_scans} scans have the board in both sensors (need {min_poses})",
        None if ok else "too-few-poses",
        None
        if ok
        else f"capture {min_poses - n_accepted} more poses with the board inside the "
        "station box and its whole pattern in the image",
    )


def observability_gate(normals_lidar: np.ndarray, min_spread: float = MIN_NORMAL_SPREAD) -> GateResult:
    """``normals_lidar``: (n, 3) unit board normals in the LiDAR frame."""
    N = np.asarray(normals_lidar, np.float64).reshape(-1, 3)
    if len(N) < 3:
        return GateResult(
            "lidar-observability",
            False,
            0.0,
            min_spread,
            f"{len(N)} board normals (need 3)",
            "unobservable",
            "capture boards at three or more different tilts",
        )
    _, s, Vt = np.linalg.svd(N, full_matrices=False)
    spread = float(s[-1] / np.sqrt(len(N)))
    weak = Vt[-1]
    mean_n = N.mean(axis=0)
    detail: dict[str, float | int | str | list[str]] = {
        "singular_values": [f"{v:.3f}" for v in s],
        "weakest_direction": _direction(weak),
    }
    if spread >= min_spread:
        return GateResult(
            "lidar-observability",
            True,
            spread,
            min_spread,
            f"board normals spread {spread:.3f} along the weakest direction {_direction(weak)}",
            detail=detail,
        )
    # tilting about an axis perpendicular to both the normal and the weak direction spreads the normals
    # along the weak direction; name that axis in words an operator can act on
    axis = np.cross(mean_n, weak)
    vertical = abs(axis[2]) > max(abs(axis[0]), abs(axis[1]))
    hint = (
        "tilt the board about its vertical axis (turn it left and right, ~20-30 degrees) between poses"
        if vertical
        else "tilt the board forward and back (about its horizontal axis, ~20 degrees) between poses"
    )
    return GateResult(
        "lidar-observability",
        False,
        spread,
        min_spread,
        f"the boards all face one way: normals spread only {spread:.3f} along {_direction(weak)}; the "
        f"translation along that direction and the rotation about the shared normal are unobservable",
        "unobservable",
        hint,
        detail,
    )


def range_spread_gate(ranges_m: Sequence[float], min_spread_m: float = MIN_RANGE_SPREAD_M) -> GateResult:
    r = np.asarray(ranges_m, np.float64)
    spread = float(r.max() - r.min()) if len(r) else 0.0
    ok = spread >= min_spread_m
    near = float(r.min()) if len(r) else 0.0
    return GateResult(
        "lidar-range-spread",
        ok,
        spread,
        min_spread_m,
        f"board ranges {near:.2f}-{near + spread:.2f} m (spread {spread:.2f} m, need {min_spread_m:.2f})",
        None if ok else "narrow-range",
        None
        if ok
        else f"add poses nearer and farther: bring it closer than {max(near - 0.3, 1.0):.1f} m "
        f"and take some beyond {near + spread + 0.5:.1f} m",
    )


def plane_rms_gate(rms_mm: float, max_mm: float = MAX_PLANE_RMS_MM) -> GateResult:
    ok = rms_mm <= max_mm
    return GateResult(
        "lidar-plane-rms",
        ok,
        rms_mm,
        max_mm,
        f"point-to-plane RMS {rms_mm:.1f} mm (max {max_mm:.0f})",
        None if ok else "plane-rms",
        None
        if ok
        else "a board point lies far from the plane the camera sees: check the camera's calibration, "
        "the board's flatness and that the scans and images were taken together",
    )


def dimension_gate(errors_mm: np.ndarray, max_mm: float = MAX_DIMENSION_ERROR_MM) -> GateResult:
    """``errors_mm``: (n, 2) measured - registered width and height per accepted pose."""
    e = np.asarray(errors_mm, np.float64).reshape(-1, 2)
    mean = e.mean(axis=0) if len(e) else np.zeros(2)
    worst = float(np.max(np.abs(mean)))
    ok = worst <= max_mm
    return GateResult(
        "lidar-dimension",
        ok,
        worst,
        max_mm,
        f"mean board dimension error width {mean[0]:+.1f} mm, height {mean[1]:+.1f} mm (max {max_mm:.0f})",
        None if ok else "dimension-error",
        None
        if ok
        else "the LiDAR sees the board bigger or smaller than registered: check --backing-mm, then the "
        "LiDAR's range offset (try --range-offset-mm)",
    )


def held_out_gate(held_out_mm: float, in_sample_mm: float, ratio: float = MAX_HELD_OUT_RATIO) -> GateResult:
    limit = ratio * in_sample_mm
    ok = bool(np.isfinite(held_out_mm)) and held_out_mm <= limit
    return GateResult(
        "lidar-held-out",
        ok,
        held_out_mm,
        limit,
        f"held-out point-to-plane RMS {held_out_mm:.1f} mm vs in-sample {in_sample_mm:.1f} mm",
        None if ok else "held-out",
        None
        if ok
        else "poses left out disagree with the rest: a few poses dominate the answer; capture more, varied "
        "poses",
    )
