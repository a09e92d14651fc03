"""The equidistant Kannala-Brandt fisheye lens (OpenCV's fisheye module): projection, inverse, focal guess.

Model (OpenCV ``cv::fisheye``, ROS ``equidistant``): a camera-frame point (X, Y, Z) at angle
theta = atan2(sqrt(X^2 + Y^2), Z) from the optical axis lands at the distorted angle
    theta_d = theta * (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
and u = fx * theta_d * X / r + cx, v = fy * theta_d * Y / r + cy (r = sqrt(X^2 + Y^2); skew 0).
``project_equidistant`` uses atan2, so it is right beyond 90 deg (a 190 deg lens images points behind
the camera plane); cv2.fisheye.projectPoints computes theta = atan(r / Z), which agrees for Z > 0 only.
The solve uses OpenCV's projection and its Jacobian, so a corner behind the camera plane (theta >= 90
deg) cannot be fitted by it: ``MAX_SOLVE_THETA_RAD`` says which corners the solve keeps.

Focal guess (cv2.fisheye diverges without one): with k = 0 and the principal point at the image centre,
a candidate f maps every corner to a pinhole ray tan(r_px / f); only at the right f do the rays of one
planar board fit a homography. ``focal_guess_px`` scores candidates by the pixel RMS of that fit
(median over views, so one broken view does not move it) on a log grid, then refines the minimum.

Scores asked again: the grid depends on the image size alone and every fisheye solve of one session (the
tilt lens, the projection gate, each held-out fold, the one-camera groups, ``--model auto``'s rung) picks its
guess views from the same corners, so most of a calibrate's view scores are asked before (96 views at
--model fisheye: 12880 asked, 5013 different). A view's score at f is a function of its corners, f and the
image centre alone; the last RECENT_VIEW_SCORES are remembered by a digest of those values
(``core.intrinsics.recent_answers``), and a score asked again is the first one, number for number.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial

import cv2
import numpy as np

from calibctl.core.intrinsics.recent_answers import RecentAnswers, values_digest
from calibctl.core.lm import Damping, DenseSystem, solve_lm

# Corners within this angle of the axis set up the focal guess (tan() is steep beyond it).
MAX_GUESS_THETA_RAD = np.deg2rad(75.0)
# cv2.fisheye's projection folds points with Z <= 0 onto the front; stay clear of 90 deg.
MAX_SOLVE_THETA_RAD = np.deg2rad(88.0)
_GRID = 24
GUESS_VIEWS = 10
POSE_ITERATIONS = 10
POSE_TOLERANCE = (
    1e-12  # relative fall of the squared residual sum below which a pose step only chases rounding
)
POSE_STEP = 1e-12  # rad / m: a smaller step only chases rounding
# Gauss-Newton (which this replaced) while steps lower the cost; damping only when a step overshoots
POSE_DAMPING = Damping(initial=1e-9)
# view scores remembered (module docstring): ~100 bytes each, so ~2 MB at most; a 96-view --model fisheye
# calibrate asks 5013 different ones
RECENT_VIEW_SCORES = 16384
_RECENT_SCORES: RecentAnswers[float] = RecentAnswers(RECENT_VIEW_SCORES)


def distort_theta(theta: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """theta_d of theta (rad) for k1..k4 (4,)."""
    t2 = theta * theta
    k1, k2, k3, k4 = (float(v) for v in np.asarray(dist, np.float64).ravel()[:4])
    return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))


def project_equidistant(points_cam: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame points -> (N, 2) float64 px, valid over the whole sphere but the back pole."""
    p = np.asarray(points_cam, np.float64).reshape(-1, 3)
    r = np.hypot(p[:, 0], p[:, 1])
    theta = np.arctan2(r, p[:, 2])
    scale = np.where(
        r > 1e-15, distort_theta(theta, dist) / np.maximum(r, 1e-300), 1.0 / np.maximum(p[:, 2], 1e-300)
    )
    return np.stack([K[0, 0] * p[:, 0] * scale + K[0, 2], K[1, 1] * p[:, 1] * scale + K[1, 2]], axis=1)


def undistort_theta(theta_d: np.ndarray, dist: np.ndarray, iterations: int = 20) -> np.ndarray:
    """theta of theta_d (rad) by Newton's method from theta = theta_d (the lens is monotonic where it
    images)."""
    theta_d = np.asarray(theta_d, np.float64)
    theta = theta_d.copy()
    k = np.asarray(dist, np.float64).ravel()[:4]
    for _ in range(iterations):
        t2 = theta * theta
        f = distort_theta(theta, k) - theta_d
        df = 1.0 + t2 * (3 * k[0] + t2 * (5 * k[1] + t2 * (7 * k[2] + t2 * 9 * k[3])))
        theta = theta - f / np.where(np.abs(df) > 1e-12, df, 1e-12)
    return theta


def pixel_rays(pixels: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(N, 2) px -> (N, 3) unit rays in the camera frame (inverse of project_equidistant)."""
    px = np.asarray(pixels, np.float64).reshape(-1, 2)
    a = (px[:, 0] - K[0, 2]) / K[0, 0]
    b = (px[:, 1] - K[1, 2]) / K[1, 1]
    theta_d = np.hypot(a, b)
    theta = undistort_theta(theta_d, dist)
    s = np.where(theta_d > 1e-15, np.sin(theta) / np.maximum(theta_d, 1e-300), 1.0)
    return np.stack([a * s, b * s, np.cos(theta)], axis=1)


def project_with_jacobian(
    obj: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, intr: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) px and the (2N, 14) Jacobian [fx fy cx cy k1..k4 | rvec tvec] of one view."""
    K = np.array([[intr[0], 0.0, intr[2]], [0.0, intr[1], intr[3]], [0.0, 0.0, 1.0]])
    px, J = cv2.fisheye.projectPoints(
        obj.reshape(-1, 1, 3), rvec.reshape(3, 1), tvec.reshape(3, 1), K, intr[4:8]
    )
    return px.reshape(-1, 2), J[:, :14]


def project_fisheye(
    obj: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray
) -> np.ndarray:
    """(N, 3) board points -> (N, 2) float64 px through the fisheye model (cv2.fisheye, theta < 90 deg)."""
    K = np.asarray(camera_matrix, np.float64)
    intr = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *np.asarray(dist_coeffs, np.float64).ravel()[:4]])
    return project_with_jacobian(
        np.asarray(obj, np.float64), np.asarray(rvec, np.float64), np.asarray(tvec, np.float64), intr
    )[0]


def fisheye_pose(
    obj: np.ndarray, img: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """T_cam_board (rvec, tvec) of one view with the lens frozen; None when the corners give no pose.

    obj: (N, 3) board m, img: (N, 2) px. Uses the corners within MAX_GUESS_THETA_RAD of the axis
    (all of them when fewer than 6 are) turned into pinhole rays, then solvePnP on those rays.
    """
    K = np.asarray(camera_matrix, np.float64)
    D = np.asarray(dist_coeffs, np.float64).ravel()[:4]
    und = cv2.fisheye.undistortPoints(img.reshape(-1, 1, 2).astype(np.float64), K, D).reshape(-1, 2)
    use = np.arctan(np.hypot(und[:, 0], und[:, 1])) < MAX_GUESS_THETA_RAD
    if use.sum() < 6:
        use[:] = True
    try:
        ok, rvec, tvec = cv2.solvePnP(obj[use], und[use], np.eye(3), None, flags=cv2.SOLVEPNP_ITERATIVE)
    except cv2.error:  # degenerate point sets (collinear, repeated) raise instead of returning False
        return None
    if not ok or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()) or tvec.ravel()[2] <= 0:
        return None
    return rvec.ravel(), tvec.ravel()


def refine_fisheye_pose(
    obj: np.ndarray,
    img: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    iterations: int = POSE_ITERATIONS,
) -> tuple[np.ndarray, np.ndarray]:
    """One pose (lens frozen) minimising the pixel residuals; returns (rvec (3,), tvec (3,) m).

    Levenberg-Marquardt on the six pose parameters (calibctl.core.lm, dense path, POSE_DAMPING),
    at most ``iterations`` steps, stopping once a step lowers the squared residual sum by less than
    POSE_TOLERANCE of it or is smaller than POSE_STEP (the Gauss-Newton loop it replaced stopped there).

    Raises:
        NumericalError: the projection is NaN or infinite at the starting pose.
    """
    K = np.asarray(camera_matrix, np.float64)
    intr = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *np.asarray(dist_coeffs, np.float64).ravel()[:4]])
    residual_px = np.asarray(img, np.float64).reshape(-1, 2)

    def evaluate(pose: np.ndarray) -> DenseSystem:
        proj, J = project_with_jacobian(obj, pose[:3], pose[3:], intr)
        return DenseSystem.from_jacobian(J[:, 8:14], (residual_px - proj).reshape(-1))

    start = np.concatenate([np.ravel(rvec), np.ravel(tvec)]).astype(np.float64)
    pose = solve_lm(
        evaluate,
        start,
        lambda p, d: p + d,
        max_iterations=iterations,
        relative_tolerance=POSE_TOLERANCE,
        step_tolerance=POSE_STEP,
        damping=POSE_DAMPING,
        label="the fisheye board pose",
    ).params
    return pose[:3].copy(), pose[3:].copy()


def _homography_rms_px(obj_xy: np.ndarray, img: np.ndarray, f: float, centre: np.ndarray) -> float:
    """Pixel RMS of the best homography through the rays of one view at focal f (k = 0); nan if unusable."""
    d = img - centre
    r_px = np.hypot(d[:, 0], d[:, 1])
    theta = r_px / f
    use = theta < MAX_GUESS_THETA_RAD
    if use.sum() < 6:
        return float("nan")
    scale = np.where(r_px[use] > 1e-9, np.tan(theta[use]) / np.maximum(r_px[use], 1e-300), 1.0 / f)
    rays = d[use] * scale[:, None]
    H, _ = cv2.findHomography(obj_xy[use], rays, 0)
    if H is None or not np.isfinite(H).all():
        return float("nan")
    q = cv2.perspectiveTransform(obj_xy[use].reshape(-1, 1, 2), H).reshape(-1, 2)
    rq = np.hypot(q[:, 0], q[:, 1])
    back = q * np.where(rq > 1e-12, f * np.arctan(rq) / np.maximum(rq, 1e-300), f)[:, None]
    return float(np.sqrt(np.mean(np.sum((back - d[use]) ** 2, axis=1))))


class _ViewScores:
    """The views' homography RMS at any focal f, each view's digest taken once (the scores remembered by
    it)."""

    def __init__(
        self,
        object_points_per_view: Sequence[np.ndarray],
        image_points_per_view: Sequence[np.ndarray],
        image_size: tuple[int, int],
    ) -> None:
        self.centre = np.array([(image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0])
        self.views = [
            (np.asarray(o, np.float64).reshape(-1, 3)[:, :2], np.asarray(i, np.float64).reshape(-1, 2))
            for o, i in zip(object_points_per_view, image_points_per_view, strict=True)
        ]
        self.keys = [values_digest([o], [i], self.centre.tobytes()) for o, i in self.views]

    def at(self, f: float) -> np.ndarray:
        f_bytes = np.float64(f).tobytes()  # the exact f: a score is remembered for that f only
        return np.array(
            [
                _RECENT_SCORES.answer(key + f_bytes, partial(_homography_rms_px, o, i, f, self.centre))
                for key, (o, i) in zip(self.keys, self.views, strict=True)
            ]
        )


def view_guess_rms_px(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    f: float,
) -> np.ndarray:
    """(V,) each view's homography RMS at focal f (nan: fewer than 6 corners inside MAX_GUESS_THETA_RAD)."""
    return _ViewScores(object_points_per_view, image_points_per_view, image_size).at(f)


def forget_view_scores() -> None:
    """Forget the remembered view scores: a benchmark that times the focal guess again must compute it
    again."""
    _RECENT_SCORES.clear()


def focal_guess_px(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
) -> float | None:
    """Equidistant focal length (px) whose rays best fit one homography per view; None when no f works.

    Searches f over [max(W, H) / 8, 2 max(W, H)] (fields of view from ~400 deg down to ~30 deg).
    """
    size = float(max(image_size))
    # a dozen views pin one number down; spread over the capture, they keep the guess cheap
    pick = np.unique(
        np.linspace(0, len(image_points_per_view) - 1, min(GUESS_VIEWS, len(image_points_per_view)))
        .round()
        .astype(int)
    ).tolist()
    views = _ViewScores(
        [object_points_per_view[i] for i in pick], [image_points_per_view[i] for i in pick], image_size
    )

    def score(f: float) -> float:
        rms = views.at(f)
        rms = rms[np.isfinite(rms)]
        # fewer usable views at a small f must not win by dropping the hard ones
        return float(np.median(rms)) if rms.size >= max(1, len(views.views) // 2) else float("inf")

    grid = np.geomspace(size / 8.0, 2.0 * size, _GRID)
    scores = np.array([score(f) for f in grid])
    if not np.isfinite(scores).any():
        return None
    i = int(np.argmin(scores))
    lo, hi = float(grid[max(i - 1, 0)]), float(grid[min(i + 1, _GRID - 1)])
    g = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    fa, fb = score(a), score(b)
    for _ in range(20):  # golden-section search inside the bracketing grid cells, one new score per step
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = score(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = score(b)
    return float(0.5 * (lo + hi))
