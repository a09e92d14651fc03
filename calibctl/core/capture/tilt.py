"""Per-view board tilt the operator can trust, and how many distinct tilt directions a session has.

Why not the homography alone: reading tilt from ``K^-1 H`` with a guessed K and the lens ignored is
wrong where it matters. Barrel distortion bends a flat board at the image edge the way perspective
would, so near-flat edge views read 10-28 deg, and a homography from a handful of neighbouring corners
has almost no perspective signal at all (a 6-corner ChArUco patch read as 82 deg).

What is done instead (``session_tilts``):
  1. Views with fewer than ``MIN_TILT_CORNERS`` corners are not used (named, with the reason).
  2. The session's lens is fitted once with cv2.calibrateCamera under a deliberately small model:
     square pixels, k1 and k2 free, no tangential terms. The focal length starts from Zhang's closed
     form with only f free and c at the centre (``gates.estimate_focal_px``), then f is fitted, and c
     too when the session shows it clearly off the centre (a principal point 22 px off the centre tilts
     the real opencv-left-right views by 2 deg). When the session is too flat to tell f, f is held at
     the image diagonal and c at the centre (a flat board's tilt does not depend on f: K^-1 H keeps
     its columns orthogonal for any f).
     When that small model does not explain the corners (fit RMS above ``FISHEYE_TRY_RMS_PX``, or no
     plausible fit), the session's equidistant fisheye lens (calibctl.core.intrinsics.fisheye_solve) is fitted
     too and kept when it fits better: k1 and k2 cannot bend to a 150-190 deg lens past ~60 deg off-axis, and
     tilt read through them was up to 35 deg off on circular renders (benchmarks/results/capture-gates.md).
  3. Each view's pose through that lens is the better of the solve's and both planar (IPPE) solutions.
     Its tilt is the angle between the normal of its fitted pose and the optical axis.
  4. Each view's one-sigma on that normal is propagated through the pose Jacobian (intrinsics held)
     from the session's corner noise (the lens fit's RMS per coordinate, at least
     ``TILT_NOISE_FLOOR_PX``); a view whose normal is uncertain by more than ``TILT_SIGMA_MAX_DEG``
     spans too small an area to read tilt and is not used.
Measured on 400 projected views (seed lens k1 = -0.28, 0-50 deg, anywhere in the frame, 0.1 px noise):
see BENCHMARKS.md ("Tilt readout") and benchmarks/bench_tilt.py.

Directions: the direction of a view is the image azimuth (x right, y down) of the board side that is
farther from the camera. Two directions are distinct only when at least ``DISTINCT_DIRECTION_DEG``
(90 deg) apart, so three distinct directions really are three sides of the board; the count is the
largest set of tilted views whose directions are pairwise that far apart (``distinct_directions``).
"""

from __future__ import annotations

import bisect
import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from calibctl.core.intrinsics.covariance import intrinsic_covariance
from calibctl.core.intrinsics.fisheye_model import fisheye_pose, refine_fisheye_pose
from calibctl.core.intrinsics.solution import WARM_CRITERIA

MIN_TILT_CORNERS = 8
TILT_NOISE_FLOOR_PX = 0.2  # corner noise assumed at least this, even when the session fits better
TILT_SIGMA_MAX_DEG = 2.0
DISTINCT_DIRECTION_DEG = 90.0
_LENS_FLAGS = (
    cv2.CALIB_USE_INTRINSIC_GUESS
    | cv2.CALIB_FIX_PRINCIPAL_POINT
    | cv2.CALIB_FIX_ASPECT_RATIO
    | cv2.CALIB_ZERO_TANGENT_DIST
    | cv2.CALIB_FIX_K3
)
_MAX_CENTRE_SHIFT_FRAC = 0.2  # a principal point farther off the centre than this is a failed fit
_MAX_LENS_RMS_PX = 10.0  # above this the small lens model explains nothing; fall back to a pinhole
# above this fit RMS the small model is tried against the equidistant fisheye lens, the better one kept
FISHEYE_TRY_RMS_PX = 1.0
# c is freed only this many of OpenCV's sigmas off the centre: that sigma ignores the small model's own
# error (no k3), which moved c 8 "sigma" on one rendered session; real off-centre lenses show 15-50
_CENTRE_SIGNIFICANT_SIGMA = 10.0


@dataclass(frozen=True)
class SessionLens:
    """The small lens model tilt is read through.

    camera_matrix: (3, 3) px; dist_coeffs: (5,) OpenCV order; noise_px: corner noise per coordinate the
    tilt sigmas assume (fit RMS / sqrt 2, at least TILT_NOISE_FLOOR_PX).
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    source: str  # "session" (f, k1, k2 fitted), "nominal" (f = diagonal, k1, k2 fitted), "given", "pinhole",
    # "fisheye" (equidistant fx fy cx cy k1..k4 fitted: dist_coeffs is then (4,) cv2.fisheye order)
    noise_px: float = TILT_NOISE_FLOOR_PX

    @property
    def fisheye(self) -> bool:
        return self.source == "fisheye"

    @property
    def focal_px(self) -> float:
        return float(self.camera_matrix[0, 0])


@dataclass(frozen=True)
class ViewTilt:
    """Tilt of one view, or why it has none.

    Attributes:
        tilt_deg / direction_deg / sigma_deg: None when ``unused_reason`` is set.
        unused_reason: "too few corners (N, need 8)" or "corners span too small an area (...)".
    """

    tilt_deg: float | None
    direction_deg: float | None
    sigma_deg: float | None
    unused_reason: str | None = None

    @property
    def used(self) -> bool:
        return self.unused_reason is None


def normal_tilt_direction(rvec: np.ndarray) -> tuple[float, float]:
    """(tilt_deg, direction_deg) of a board pose (OpenCV rvec of T_cam_board)."""
    n = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0][:, 2]
    m = -n if n[2] > 0 else n  # camera-facing normal: it leans toward the far side
    tilt = math.degrees(math.acos(min(1.0, abs(float(n[2])))))
    return tilt, math.degrees(math.atan2(m[1], m[0])) % 360.0


def normal_sigma_deg(
    object_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, lens: SessionLens
) -> float:
    """One-sigma (deg) of the board normal of one view: pose covariance from the Jacobian, intrinsics held.

    Args:
        object_points: (N, 3) float64 board frame. rvec, tvec: (3,) the view's fitted pose.
    """
    _, J = _project(object_points, rvec, tvec, lens)
    info = J.T @ J
    if not np.isfinite(info).all() or np.linalg.cond(info) > 1e15:
        return math.inf
    cov_r = lens.noise_px**2 * np.linalg.inv(info)[:3, :3]
    r0 = np.asarray(rvec, np.float64).reshape(3)
    n0 = cv2.Rodrigues(r0)[0][:, 2]
    eps = 1e-7
    Jn = np.column_stack([(cv2.Rodrigues(r0 + eps * e)[0][:, 2] - n0) / eps for e in np.eye(3)])
    return math.degrees(math.sqrt(max(0.0, float(np.trace(Jn @ cov_r @ Jn.T)))))


def _project(
    object_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, lens: SessionLens
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) px of the board points through ``lens`` and the (2N, 6) Jacobian on [rvec tvec]."""
    obj = np.asarray(object_points, np.float64).reshape(-1, 1, 3)
    r = np.asarray(rvec, np.float64).reshape(3, 1)
    t = np.asarray(tvec, np.float64).reshape(3, 1)
    if lens.fisheye:  # cv2.fisheye's Jacobian: [f(2) c(2) k(4) | om(3) T(3) | alpha]
        px, J = cv2.fisheye.projectPoints(obj, r, t, lens.camera_matrix, lens.dist_coeffs)
        return px.reshape(-1, 2), J[:, 8:14]
    px, J = cv2.projectPoints(obj, r, t, lens.camera_matrix, lens.dist_coeffs)
    return px.reshape(-1, 2), J[:, :6]


def nominal_camera(image_size: tuple[int, int], focal_px: float) -> np.ndarray:
    """(3, 3) K with ``focal_px`` and the principal point at the image centre."""
    width, height = image_size
    return np.array([[focal_px, 0.0, (width - 1) / 2], [0.0, focal_px, (height - 1) / 2], [0.0, 0.0, 1.0]])


def fit_session_lens(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    focal_px: float | None,
    focal_source: str,
) -> tuple[SessionLens, list[np.ndarray], list[np.ndarray]]:
    """The session's small lens model and every view's pose through it (see the module docstring).

    Args:
        object_points: V arrays (N_i, 3) board frame. image_points: V arrays (N_i, 2) px.
        focal_px: the starting focal length; held fixed unless ``focal_source`` is "session".

    Returns:
        (lens, rvecs, tvecs): one (3,) rvec and tvec per view.
    """
    diag = math.hypot(*image_size)
    K0 = nominal_camera(image_size, focal_px if focal_px is not None else diag)
    fit = None
    K_start, D_start = K0, None
    if focal_source == "session":
        # c free; kept only when it is significantly off the centre (else a weak session lets c wander)
        fit = _calibrate(
            object_points, image_points, image_size, K0, _LENS_FLAGS & ~cv2.CALIB_FIX_PRINCIPAL_POINT
        )
        if fit is not None and np.all(
            np.abs(fit[1][:2, 2] - K0[:2, 2])
            < _CENTRE_SIGNIFICANT_SIGMA * _centre_sigma_px(object_points, image_points, fit)
        ):
            if _plausible(fit, K0, image_size):
                # c is the centre's within its noise: the c-fixed fit starts from this one's focal length
                # and distortion, next to its minimum (the cold start's, benchmarks/results/station.md)
                K_start, D_start = K0.copy(), fit[2]
                K_start[0, 0], K_start[1, 1] = fit[1][0, 0], fit[1][1, 1]
            fit = None
    if fit is None:
        fit = _calibrate(
            object_points,
            image_points,
            image_size,
            K_start,
            _LENS_FLAGS | (0 if focal_source == "session" else cv2.CALIB_FIX_FOCAL_LENGTH),
            D_start,
        )
    plausible = fit is not None and _plausible(fit, K0, image_size)
    if not plausible or (fit is not None and fit[0] > FISHEYE_TRY_RMS_PX):
        fisheye = _fit_fisheye(object_points, image_points, image_size)
        if fisheye is not None and (not plausible or (fit is not None and fisheye[0] < fit[0])):
            rms, K, D, rvecs, tvecs = fisheye
            lens = SessionLens(K, D, "fisheye", max(TILT_NOISE_FLOOR_PX, rms / math.sqrt(2.0)))
            poses = [
                best_pose(o, i, lens, r, t)
                for o, i, r, t in zip(object_points, image_points, rvecs, tvecs, strict=True)
            ]
            return lens, [r for r, _ in poses], [t for _, t in poses]
    if not plausible:  # neither lens model fitted: read tilt through a pinhole
        lens = SessionLens(K0, np.zeros(5), "pinhole", TILT_NOISE_FLOOR_PX)
        poses = [best_pose(o, i, lens) for o, i in zip(object_points, image_points, strict=True)]
        return lens, [r for r, _ in poses], [t for _, t in poses]
    assert fit is not None
    rms, K, D, rvecs, tvecs = fit
    lens = SessionLens(K, D, focal_source, max(TILT_NOISE_FLOOR_PX, rms / math.sqrt(2.0)))
    poses = [
        best_pose(o, i, lens, r, t)
        for o, i, r, t in zip(object_points, image_points, rvecs, tvecs, strict=True)
    ]
    return lens, [r for r, _ in poses], [t for _, t in poses]


_Fit = tuple[float, np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]]


def _fit_fisheye(
    object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray], image_size: tuple[int, int]
) -> _Fit | None:
    """(rms px, K, k1..k4, rvecs, tvecs) of the equidistant lens (calibctl.core.intrinsics.fisheye_solve), or
    None when it cannot be initialised, fails or lands off the image. Asked through ``solve_intrinsics``,
    which remembers it: the projection gate solves the same views with the same fisheye model when the session
    is solved as fisheye or its lens is unknown (--model auto, a plain capture), and gets this solve."""
    from calibctl.core.intrinsics.solve import (
        solve_intrinsics,  # only for sessions the small model cannot explain
    )
    from calibctl.errors import CalibctlError

    try:
        sol = solve_intrinsics(object_points, image_points, image_size, "fisheye")
    except (CalibctlError, cv2.error, np.linalg.LinAlgError):
        return None
    K = np.asarray(sol.camera_matrix, np.float64)
    if not (
        math.isfinite(sol.rms_px)
        and sol.rms_px < _MAX_LENS_RMS_PX
        and bool(
            np.all(
                np.abs(K[:2, 2] - nominal_camera(image_size, 1.0)[:2, 2])
                <= _MAX_CENTRE_SHIFT_FRAC * np.asarray(image_size)
            )
        )
    ):
        return None
    return (
        float(sol.rms_px),
        K,
        np.asarray(sol.dist_coeffs, np.float64).copy(),
        [np.ravel(r) for r in sol.rvecs],
        [np.ravel(t) for t in sol.tvecs],
    )


def _plausible(fit: _Fit, K0: np.ndarray, image_size: tuple[int, int]) -> bool:
    """A small-model fit that explains the views: RMS, focal length, k1 and centre in their bounds."""
    diag = math.hypot(*image_size)
    return (
        fit[0] < _MAX_LENS_RMS_PX
        and 0.2 * diag <= fit[1][0, 0] <= 5 * diag
        and abs(fit[2][0]) < 2.0
        and bool(np.all(np.abs(fit[1][:2, 2] - K0[:2, 2]) <= _MAX_CENTRE_SHIFT_FRAC * np.asarray(image_size)))
    )


def _calibrate(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    K0: np.ndarray,
    flags: int,
    D0: np.ndarray | None = None,
) -> _Fit | None:
    """(rms px, K, dist (5,), rvecs, tvecs) of cv2.calibrateCamera, or None when it fails or is not finite.
    ``D0``: a warm start (with ``K0``) next to the minimum, stopped at ``WARM_CRITERIA``."""
    stop: dict[str, Any] = {} if D0 is None else {"criteria": WARM_CRITERIA}
    try:
        rms, K, D, rvecs, tvecs = cv2.calibrateCamera(
            [np.asarray(o, np.float32).reshape(-1, 3) for o in object_points],
            [np.asarray(i, np.float32).reshape(-1, 2) for i in image_points],
            (int(image_size[0]), int(image_size[1])),
            K0.copy(),
            np.zeros(5) if D0 is None else np.array(D0, np.float64),
            flags=flags,
            **stop,
        )
    except cv2.error:
        return None
    K, D = np.asarray(K, np.float64), np.asarray(D, np.float64).ravel()[:5]
    if not (math.isfinite(rms) and np.isfinite(K).all() and np.isfinite(D).all()):
        return None
    return float(rms), K, D, [np.ravel(r) for r in rvecs], [np.ravel(t) for t in tvecs]


def _centre_sigma_px(
    object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray], fit: _Fit
) -> np.ndarray:
    """(2,) one-sigma of (cx, cy) of a c-free fit, poses eliminated (calibctl.core.intrinsics.covariance):
    linear in the view count, where OpenCV's calibrateCameraExtended inverts every pose too (5 s at 100
    views)."""
    _, K, D, rvecs, tvecs = fit
    objs = [np.asarray(o, np.float64).reshape(-1, 3) for o in object_points]
    residuals = [
        np.asarray(i, np.float64).reshape(-1, 2) - cv2.projectPoints(o, r, t, K, D)[0].reshape(-1, 2)
        for o, i, r, t in zip(objs, image_points, rvecs, tvecs, strict=True)
    ]
    dof = 2 * sum(len(o) for o in objs) - 6 * len(objs) - 5
    cov = intrinsic_covariance(
        objs,
        np.array(rvecs),
        np.array(tvecs),
        K,
        D,
        residuals,
        ("fx", "fy", "cx", "cy"),
        ("k1", "k2"),
        float(K[0, 0] / K[1, 1]),
        max(dof, 1),
    )
    if cov.covariance is None:
        return np.full(2, np.inf)
    return np.sqrt(np.diag(cov.covariance))[[cov.names.index("cx"), cov.names.index("cy")]]


def best_pose(
    object_points: np.ndarray,
    image_points: np.ndarray,
    lens: SessionLens,
    rvec: np.ndarray | None = None,
    tvec: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The view's pose through ``lens`` with the lowest reprojection error: both planar IPPE solutions
    and the given one. A plain LM from a homography start can settle in the mirrored local minimum (a
    27 deg view read 10 deg); IPPE returns both branches of the planar ambiguity."""
    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    img = np.asarray(image_points, np.float64).reshape(-1, 2)
    candidates = [] if rvec is None or tvec is None else [(np.ravel(rvec), np.ravel(tvec))]
    with contextlib.suppress(cv2.error):
        if lens.fisheye:  # IPPE on the corners turned into pinhole rays (normalised, K = I)
            rays = cv2.fisheye.undistortPoints(img.reshape(-1, 1, 2), lens.camera_matrix, lens.dist_coeffs)
            _, rvecs, tvecs, _ = cv2.solvePnPGeneric(
                obj, rays.reshape(-1, 2), np.eye(3), None, flags=cv2.SOLVEPNP_IPPE
            )
        else:
            _, rvecs, tvecs, _ = cv2.solvePnPGeneric(
                obj, img, lens.camera_matrix, lens.dist_coeffs, flags=cv2.SOLVEPNP_IPPE
            )
        candidates += [(np.ravel(r), np.ravel(t)) for r, t in zip(rvecs, tvecs, strict=True)]
    if not candidates and lens.fisheye:
        pose = fisheye_pose(obj, img, lens.camera_matrix, lens.dist_coeffs)
        candidates = [] if pose is None else [pose]
    if not candidates:
        _, r, t = cv2.solvePnP(obj, img, lens.camera_matrix, lens.dist_coeffs)
        candidates = [(np.ravel(r), np.ravel(t))]

    def error(pose: tuple[np.ndarray, np.ndarray]) -> float:
        return float(np.sum((_project(obj, pose[0], pose[1], lens)[0] - img) ** 2))

    r, t = min(candidates, key=error)
    if lens.fisheye:
        return refine_fisheye_pose(obj, img, lens.camera_matrix, lens.dist_coeffs, r, t)
    r, t = cv2.solvePnPRefineLM(obj, img, lens.camera_matrix, lens.dist_coeffs, r.copy(), t.copy())
    return np.asarray(r, np.float64).ravel(), np.asarray(t, np.float64).ravel()


def session_tilts(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    focal_px: float | None,
    focal_source: str,
) -> tuple[list[ViewTilt], SessionLens | None]:
    """Tilt, direction and one-sigma of every view (None + reason for a view that cannot give one).

    Args and focal_source as ``fit_session_lens``. Returns (per-view tilts, the lens; None when no view
    has enough corners).
    """
    enough = [i for i, o in enumerate(object_points) if len(o) >= MIN_TILT_CORNERS]
    tilts = [
        ViewTilt(None, None, None, f"too few corners ({len(o)}, need {MIN_TILT_CORNERS})")
        for o in object_points
    ]
    if not enough:
        return tilts, None
    lens, rvecs, tvecs = fit_session_lens(
        [object_points[i] for i in enough],
        [image_points[i] for i in enough],
        image_size,
        focal_px,
        focal_source,
    )
    for i, rvec, tvec in zip(enough, rvecs, tvecs, strict=True):
        sigma = normal_sigma_deg(object_points[i], rvec, tvec, lens)
        if sigma > TILT_SIGMA_MAX_DEG:
            shown = "unbounded" if not math.isfinite(sigma) else f"+/- {sigma:.1f} deg"
            tilts[i] = ViewTilt(
                None,
                None,
                None,
                f"corners span too small an area to read tilt ({shown} at "
                f"{lens.noise_px:.2f} px corner noise, limit {TILT_SIGMA_MAX_DEG:.0f} deg)",
            )
            continue
        tilt, direction = normal_tilt_direction(rvec)
        tilts[i] = ViewTilt(tilt, direction, sigma)
    return tilts, lens


def angular_gap_deg(a: float, b: float) -> float:
    """Smallest angle between two directions, 0..180 deg."""
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


def distinct_directions(
    directions_deg: Sequence[float], min_gap_deg: float = DISTINCT_DIRECTION_DEG
) -> list[float]:
    """The largest subset of directions that are pairwise at least ``min_gap_deg`` apart (ascending).

    On a circle, for a fixed first element the greedy "next one at least min_gap further" chain is the
    longest; trying every element as the first gives the optimum. At most 360 / min_gap elements.
    """
    angles = sorted({round(float(a) % 360.0, 6) for a in directions_deg})
    doubled = angles + [a + 360.0 for a in angles]  # unrolled once, so the chain can run past 360
    best: list[float] = []
    for start in angles:
        chain, last = [start], start
        while True:
            # the next angle at least min_gap past the last one that still leaves min_gap back to the start
            k = bisect.bisect_left(doubled, last + min_gap_deg)
            if k == len(doubled) or doubled[k] > start + 360.0 - min_gap_deg:
                break
            last = doubled[k]
            chain.append(last % 360.0)
        if len(chain) > len(best):
            best = chain
    return sorted(best)


def directions_to_add(have_deg: Sequence[float], candidates_deg: Sequence[float], count: int) -> list[float]:
    """Candidate directions to ask for next: greedily the one that adds most distinct directions, then the one
    farthest from every direction collected. (Farthest alone asked opencv-left-right's left01-09 for "top
    right", 74 deg from a kept view: a board tilted exactly as told would not have passed.)"""
    taken = [float(a) for a in have_deg]
    chosen: list[float] = []
    for _ in range(max(0, count)):
        free = [c for c in candidates_deg if c not in chosen]
        if not free:
            break
        best = max(
            free,
            key=lambda c: (
                len(distinct_directions([*taken, c])),
                min((angular_gap_deg(c, t) for t in taken), default=180.0),
                -c,
            ),
        )
        chosen.append(best)
        taken.append(best)
    return chosen
