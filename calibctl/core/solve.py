"""Intrinsic calibration: cv2.calibrateCameraExtended on stored corners, with honest uncertainty.

Units and conventions: pixels with the top-left pixel's centre at (0, 0) (OpenCV), model points in
the board frame in metres (any unit works: only ``tvecs`` carry it), distortion in OpenCV order
``k1, k2, p1, p2, k3[, k4, k5, k6]`` applied in normalised coordinates.

``rms_px`` is OpenCV's definition: sqrt(sum over corners of the squared 2-D residual / number of
corners), i.e. a per-corner RMS, not per coordinate (per coordinate is rms_px / sqrt(2)).

Uncertainty
    sigma comes from calibctl.core.covariance (Jacobian at the solution, poses eliminated by the
    Schur complement, observability decided on a scaled matrix), not from OpenCV's
    stdDeviationsIntrinsics, which reports near-zero sigma(fx) for nearly fronto-parallel captures
    (see that module). On well-posed data the two agree to well under 1 %; OpenCV's raw numbers
    are kept in ``sigma_opencv`` for reference.

sigma(fx) under CALIB_FIX_ASPECT_RATIO
    OpenCV solves for fy only and keeps fx = a * fy with a = fx/fy of the initial camera matrix
    (1.0 when no initial matrix is given), and reports 0 for sigma(fx). The one free focal
    parameter's Jacobian column is a * dr/dfx + dr/dfy, and fx is an exact linear function of it,
    so sigma(fx) = a * sigma(fy), which is what we record.
    Checked by benchmarks/bench_sigma_fx_tied.py (Monte-Carlo over the corner noise with fixed
    poses, 400 trials, 18 views, 0.2 px, a = 1.00 and 1.03): mean reported a * sigma(fy) /
    empirical std(fx_est) = 0.965 and 0.966 (Monte-Carlo standard error 3.5 %); the un-tied solve
    of the same draws has sigma(fx) 9 % larger (1.063 vs 0.972 px) and the same 0.97 ratio.
    fx/fy = a held to machine precision in every trial.

Initial guess of the rational model
    Started cold (OpenCV's own homography initialisation, all eight coefficients at 0), the rational
    model can stop in a bad minimum on a wide lens: on a 190 deg circular render (tests/core/test_solve.py)
    RMS 4.39 px against 0.276 px from a warm start. Without an ``initial`` K it therefore starts from the
    k1k2 solution's K (CALIB_USE_INTRINSIC_GUESS); where k1k2 itself cannot be solved it starts cold.
    On opencv-left-right, udacity-camcal and 120-170 deg renders the warm and the cold start reach the
    same minimum (RMS equal to 1e-3 px).

Determinism
    OpenCV parallelises parts of the solve; with 2+ threads the summation order varies and the
    same input gives results differing around 1e-10 px. The solve runs with cv2.setNumThreads(1)
    (restored afterwards), which makes it bit-identical run to run.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from calibctl.core.covariance import IntrinsicCovariance, intrinsic_covariance
from calibctl.core.fisheye_model import fisheye_pose, project_fisheye, refine_fisheye_pose
from calibctl.errors import InputError, NumericalError, UsageError

# Below this many degrees of freedom (residuals - parameters) the residual variance that scales
# the covariance is itself too uncertain: its relative std is sqrt(2 / dof), 20 % at 50.
MIN_SIGMA_DOF = 50
NO_UNCERTAINTY = "not computed: a fit solved only for its numbers (uncertainty=False)"
# OpenCV needs a homography per view for its initial guess: at least 4 corners.
MIN_CORNERS_PER_VIEW = 4
# A solve is declared diverged when it leaves the space of plausible pinhole cameras:
# focal length under MIN_FOCAL_FRAC * max(W, H) (a field of view over ~160 deg, which the
# pinhole + polynomial models cannot represent anyway), principal point more than one image size
# outside the image, or an RMS above MAX_RMS_PX (50x a sub-pixel detector's; the model explains
# nothing: mis-ordered corners, mixed boards, wrong board geometry).
MIN_FOCAL_FRAC = 0.1
MAX_RMS_PX = 10.0

# Index of each parameter in OpenCV's stdDeviationsIntrinsics (and in the distortion vector + 4).
_STD_INDEX = {"fx": 0, "fy": 1, "cx": 2, "cy": 3, "k1": 4, "k2": 5, "p1": 6, "p2": 7, "k3": 8,
              "k4": 9, "k5": 10, "k6": 11}
DISTORTION_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
FISHEYE_DIST_NAMES = ("k1", "k2", "k3", "k4")


# OpenCV 5 names these flags at the top level; OpenCV 4.x only in cv2.fisheye, with other values. The
# fisheye solve is calibctl's own and only records them, so the OpenCV 5 values serve on both.
CALIB_RECOMPUTE_EXTRINSIC = int(getattr(cv2, "CALIB_RECOMPUTE_EXTRINSIC", 1 << 23))
CALIB_FIX_SKEW = int(getattr(cv2, "CALIB_FIX_SKEW", 1 << 25))

@dataclass(frozen=True)
class DistortionModel:
    """One row of the model table: OpenCV flags and which parameters they leave free."""

    name: str
    flags: int
    free_intrinsics: tuple[str, ...]  # fx is listed but tied to fy when fx_tied_to_fy
    free_distortion: tuple[str, ...]
    n_coeffs: int  # length of the recorded distortion vector (5 or 8)
    min_views: int
    description: str
    kind: str = "pinhole"  # "fisheye": equidistant Kannala-Brandt, solved by calibctl.core.fisheye_solve

    @property
    def fx_tied_to_fy(self) -> bool:
        return self.kind == "pinhole" and bool(self.flags & cv2.CALIB_FIX_ASPECT_RATIO)

    @property
    def n_free_intrinsic_params(self) -> int:
        """Free non-pose parameters: intrinsics (fx counts 0 when tied) + distortion."""
        return len(self.free_intrinsics) - int(self.fx_tied_to_fy) + len(self.free_distortion)


_ASPECT = cv2.CALIB_FIX_ASPECT_RATIO
_FOCAL = ("fx", "fy", "cx", "cy")
MODELS: Mapping[str, DistortionModel] = {
    m.name: m
    for m in (
        DistortionModel("k1k2", cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST | _ASPECT, _FOCAL,
                        ("k1", "k2"), 5, 3, "production default (seed ch.1): fx=fy*a, k1 k2 free"),
        DistortionModel("k1k2k3", cv2.CALIB_ZERO_TANGENT_DIST | _ASPECT, _FOCAL,
                        ("k1", "k2", "k3"), 5, 3, "k3 free, no tangential, fx=fy*a"),
        DistortionModel("k1k2p1p2k3", _ASPECT, _FOCAL,
                        ("k1", "k2", "p1", "p2", "k3"), 5, 4, "full 5-term Brown-Conrady, fx=fy*a"),
        DistortionModel("rational", cv2.CALIB_RATIONAL_MODEL | _ASPECT, _FOCAL,
                        DISTORTION_NAMES, 8, 5, "OpenCV rational 8-term model, fx=fy*a"),
        DistortionModel("opencv-default", 0, _FOCAL, ("k1", "k2", "p1", "p2", "k3"), 5, 3,
                        "plain OpenCV flags=0: fx and fy independent; for reference reproduction"),
        DistortionModel("fisheye", cv2.CALIB_USE_INTRINSIC_GUESS | CALIB_RECOMPUTE_EXTRINSIC | CALIB_FIX_SKEW,
                        _FOCAL, FISHEYE_DIST_NAMES, 4, 3,
                        "equidistant Kannala-Brandt (cv2.fisheye, ROS equidistant): fx fy cx cy k1..k4, skew 0",
                        kind="fisheye"),
    )
}
DEFAULT_MODEL = "k1k2"


def get_model(name: str) -> DistortionModel:
    """Look a model up by name; UsageError naming the choices otherwise."""
    try:
        return MODELS[name]
    except KeyError:
        raise UsageError(f"unknown distortion model {name!r}",
                         hint=f"choose one of: {', '.join(MODELS)} (or 'auto')") from None


@dataclass(frozen=True)
class IntrinsicsSolution:
    """Result of one intrinsic solve. Arrays are read-only.

    Attributes:
        model: DistortionModel name.
        image_size: (width, height) px the corners were detected at.
        camera_matrix: (3, 3) float64 K, px.
        dist_coeffs: (n_coeffs,) float64, OpenCV order k1 k2 p1 p2 k3 [k4 k5 k6].
        rms_px: OpenCV's RMS over all corners (2-D distance), px.
        per_view_rms_px: (V,) float64 per-view RMS, same definition.
        rvecs: (V, 3) float64 Rodrigues board->camera rotations. tvecs: (V, 3) board units.
        residuals_px: V arrays (N_i, 2) float64, observed - projected.
        sigma: one-sigma per FREE parameter, by name (fx fy cx cy px; k*, p* unitless). Empty
            when refused. Under a tied aspect ratio sigma['fx'] = aspect_ratio * sigma['fy'].
        sigma_refused_reason: why sigma is empty, else None.
        n_residuals: 2 * corners. n_parameters: free intrinsics + distortion + 6 per view.
        aspect_ratio: fx/fy held fixed during the solve, or None when fx and fy were free.
        covariance: the intrinsic covariance sigma comes from (calibctl.core.covariance), with
            its names, reciprocal condition number and residual variance.
        sigma_opencv: OpenCV's raw stdDeviationsIntrinsics for the free parameters, for reference
            only (0 for fx when tied; unreliable when nearly unobservable, see covariance.py).
    """

    model: str
    image_size: tuple[int, int]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rms_px: float
    per_view_rms_px: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    residuals_px: tuple[np.ndarray, ...]
    sigma: Mapping[str, float] = field(default_factory=dict)
    sigma_refused_reason: str | None = None
    n_residuals: int = 0
    n_parameters: int = 0
    aspect_ratio: float | None = None
    covariance: IntrinsicCovariance | None = None
    sigma_opencv: Mapping[str, float] = field(default_factory=dict)

    @property
    def fx(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def fy(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def cx(self) -> float:
        return float(self.camera_matrix[0, 2])

    @property
    def cy(self) -> float:
        return float(self.camera_matrix[1, 2])

    @property
    def dof(self) -> int:
        return self.n_residuals - self.n_parameters

    @property
    def n_views(self) -> int:
        return len(self.residuals_px)


@contextlib.contextmanager
def single_threaded_opencv() -> Iterator[None]:
    """Run OpenCV single-threaded inside the block (bit-identical results), restore afterwards.

    ``cv2.setNumThreads`` is process-global, so this is not a per-thread setting: code that solves on
    several Python threads enters the block once around the whole pool (``validate_holdout``). Inside
    it, nested blocks see 1 thread already and change nothing, so one thread leaving its block never
    gives OpenCV its threads back while another thread's solve is running.
    """
    previous = cv2.getNumThreads()
    if previous == 1:
        yield
        return
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(previous)


def readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


def check_inputs(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: DistortionModel,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Validate shapes, finiteness, counts; return float32 copies the way OpenCV wants them."""
    width, height = (int(v) for v in image_size)
    if width <= 0 or height <= 0 or (width, height) != tuple(image_size):
        raise InputError(f"image size must be two positive integers (width, height), got {image_size}")
    if len(object_points) != len(image_points):
        raise InputError(f"{len(object_points)} object-point views but {len(image_points)} image-point views")
    n_views = len(image_points)
    if n_views < model.min_views:
        raise NumericalError(
            f"model {model.name} needs at least {model.min_views} board views, got {n_views}",
            hint="capture more views tilted 20-40 deg in at least three directions, "
                 "or ask for a model with fewer coefficients (--model k1k2)")
    objs, imgs = [], []
    for i, (obj, img) in enumerate(zip(object_points, image_points, strict=True)):
        obj = np.asarray(obj, dtype=np.float64).reshape(-1, 3)
        img = np.asarray(img, dtype=np.float64).reshape(-1, 2)
        if obj.shape[0] != img.shape[0]:
            raise InputError(f"view {i}: {obj.shape[0]} model points but {img.shape[0]} corners")
        if not (np.isfinite(obj).all() and np.isfinite(img).all()):
            raise InputError(f"view {i}: corners or model points contain NaN or infinity",
                             hint="re-run detection for this view or drop it")
        if obj.shape[0] < MIN_CORNERS_PER_VIEW:
            raise NumericalError(f"view {i} has {obj.shape[0]} corners; at least "
                                 f"{MIN_CORNERS_PER_VIEW} are needed per view", hint="drop that view")
        outside = (img[:, 0] < -1) | (img[:, 0] > width) | (img[:, 1] < -1) | (img[:, 1] > height)
        if outside.any():
            u, v = img[np.argmax(outside)]
            raise InputError(
                f"view {i}: corner ({u:.1f}, {v:.1f}) lies outside the {width}x{height} image",
                hint="the image size must be the resolution the corners were detected at")
        objs.append(obj.astype(np.float32))
        imgs.append(img.astype(np.float32))
    return objs, imgs


def residual_rms_px(residuals: np.ndarray) -> float:
    """sqrt(mean squared 2-D residual length) of (N, 2) px, OpenCV's per-view RMS; nan for N = 0."""
    if len(residuals) == 0:
        return float("nan")
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))


def parameter_count(model: DistortionModel, n_views: int) -> int:
    """Free parameters of a solve: intrinsics + distortion + 6 pose parameters per view."""
    return model.n_free_intrinsic_params + 6 * n_views


def _opencv_sigma(model: DistortionModel, std_intrinsics: np.ndarray) -> dict[str, float]:
    std = np.asarray(std_intrinsics, dtype=np.float64).ravel()
    return {n: float(std[_STD_INDEX[n]]) for n in (*model.free_intrinsics, *model.free_distortion)}


def _sigma_by_name(cov: IntrinsicCovariance, aspect: float | None) -> tuple[dict[str, float], str | None]:
    if cov.covariance is None:
        return {}, cov.refused_reason
    sigma = dict(zip(cov.names, np.sqrt(np.diag(cov.covariance)).tolist(), strict=True))
    if aspect is not None:
        sigma = {"fx": aspect * sigma["fy"], **sigma}
    bad = [n for n, v in sigma.items() if not (math.isfinite(v) and v > 0)]
    if bad:
        return {}, f"the covariance is not finite and positive for {', '.join(bad)}"
    return sigma, None


def check_output(K: np.ndarray, dist: np.ndarray, rms: float, rvecs: np.ndarray, tvecs: np.ndarray,
                  image_size: tuple[int, int]) -> None:
    if not (np.isfinite(K).all() and np.isfinite(dist).all() and math.isfinite(rms)
            and np.isfinite(rvecs).all() and np.isfinite(tvecs).all()):
        raise NumericalError("the solve returned NaN or infinite values",
                             hint="the views do not constrain the model; capture tilted views "
                                  "or use a model with fewer coefficients")
    width, height = image_size
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    min_f = MIN_FOCAL_FRAC * max(width, height)
    if min(fx, fy) < min_f or not (-width <= cx <= 2 * width and -height <= cy <= 2 * height):
        raise NumericalError(
            f"the solve diverged: fx={fx:.4g} fy={fy:.4g} cx={cx:.4g} cy={cy:.4g} px "
            f"for a {width}x{height} image (focal length must be at least {min_f:.4g} px, "
            "principal point within one image size of the image)",
            hint="capture views tilted 20-40 deg in at least three directions covering the image")
    if rms > MAX_RMS_PX:
        raise NumericalError(
            f"the solve does not explain the corners: RMS {rms:.2f} px (limit {MAX_RMS_PX:.0f} px)",
            hint="check the corner order and that every view shows the declared board")


def solve_intrinsics(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: str | DistortionModel = DEFAULT_MODEL,
    initial: np.ndarray | None = None,
    uncertainty: bool = True,
) -> IntrinsicsSolution:
    """Solve K and distortion with cv2.calibrateCameraExtended.

    Args:
        object_points_per_view: V arrays (N_i, 3) float64, board frame (metres), z = 0.
        image_points_per_view: V arrays (N_i, 2) float64 px, matching rows.
        image_size: (width, height) px the corners were detected at.
        model: a MODELS name or a DistortionModel.
        initial: optional (3, 3) K guess (CALIB_USE_INTRINSIC_GUESS); its fx/fy is the ratio held
            under CALIB_FIX_ASPECT_RATIO. Without it the ratio is 1.
        uncertainty: False for a fit used only for its K, distortion, poses and residuals (a held-out
            fold, a group of the one-camera check): cv2.calibrateCamera runs the same Levenberg-Marquardt
            and returns bit-identical K, distortion and poses (checked on OpenCV 4.10 and 5.0), without
            the (6V + p)-square inverse behind OpenCV's standard deviations, a third of a 16-view k1k2
            solve. Such a solution has no sigma, covariance or sigma_opencv. Fisheye models ignore it.

    Raises:
        InputError: malformed, non-finite, or out-of-image input.
        NumericalError: too few views/corners for the model; OpenCV failed; diverged/non-finite output.
        UsageError: unknown model name.
    """
    m = get_model(model) if isinstance(model, str) else model
    if m.kind == "fisheye":
        from calibctl.core.fisheye_solve import solve_fisheye  # it builds on this module's types

        return solve_fisheye(object_points_per_view, image_points_per_view, image_size, m, initial)
    if initial is None and m.flags & cv2.CALIB_RATIONAL_MODEL:
        initial = _k1k2_start(object_points_per_view, image_points_per_view, image_size)
    size = (int(image_size[0]), int(image_size[1]))
    objs, imgs = check_inputs(object_points_per_view, image_points_per_view, image_size, m)
    flags = m.flags
    K0 = np.eye(3, dtype=np.float64)
    if initial is not None:
        K0 = np.array(initial, dtype=np.float64).reshape(3, 3)
        if not (np.isfinite(K0).all() and K0[0, 0] > 0 and K0[1, 1] > 0):
            raise InputError("the initial camera matrix must be finite with positive fx, fy")
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    aspect = float(K0[0, 0] / K0[1, 1]) if m.fx_tied_to_fy else None
    D0 = np.zeros(m.n_coeffs, dtype=np.float64)
    try:
        with single_threaded_opencv():
            if uncertainty:
                rms, K, D, rvecs, tvecs, std_int, _std_ext, per_view = cv2.calibrateCameraExtended(
                    objs, imgs, size, K0.copy(), D0.copy(), flags=flags)
            else:
                rms, K, D, rvecs, tvecs = cv2.calibrateCamera(objs, imgs, size, K0.copy(), D0.copy(), flags=flags)
    except cv2.error as exc:
        detail = str(exc).strip().splitlines()[-1].split(" error: ")[-1]
        raise NumericalError(f"OpenCV could not solve model {m.name}: {detail}",
                             hint="check that every view is a planar board with distinct corners") from exc
    K = np.asarray(K, dtype=np.float64)
    D_full = np.asarray(D, dtype=np.float64).ravel()
    D = np.zeros(m.n_coeffs)
    D[: min(m.n_coeffs, D_full.size)] = D_full[: m.n_coeffs]
    rv = np.asarray(rvecs, dtype=np.float64).reshape(-1, 3)
    tv = np.asarray(tvecs, dtype=np.float64).reshape(-1, 3)
    check_output(K, D, float(rms), rv, tv, size)

    residuals = []
    with single_threaded_opencv():
        for obj, img, r, t in zip(objs, imgs, rv, tv, strict=True):
            proj, _ = cv2.projectPoints(obj.astype(np.float64), r, t, K, D)
            residuals.append(readonly(img.astype(np.float64) - proj.reshape(-1, 2)))
    n_res = 2 * sum(len(o) for o in objs)
    n_par = parameter_count(m, len(objs))
    dof = n_res - n_par
    if not uncertainty:  # OpenCV's per-view RMS, from the same residuals
        return IntrinsicsSolution(
            model=m.name, image_size=size, camera_matrix=readonly(K), dist_coeffs=readonly(D), rms_px=float(rms),
            per_view_rms_px=readonly(np.array([residual_rms_px(r) for r in residuals])),
            rvecs=readonly(rv), tvecs=readonly(tv), residuals_px=tuple(residuals),
            sigma_refused_reason=NO_UNCERTAINTY, n_residuals=n_res, n_parameters=n_par, aspect_ratio=aspect)
    if dof < MIN_SIGMA_DOF:
        cov = IntrinsicCovariance((), None, float("nan"), float("nan"), (
            f"only {dof} degrees of freedom ({n_res} residuals - {n_par} parameters); at least "
            f"{MIN_SIGMA_DOF} are needed for the residual variance to mean anything"))
    else:
        cov = intrinsic_covariance([o.astype(np.float64) for o in objs], rv, tv, K, D, residuals,
                                   m.free_intrinsics, m.free_distortion, aspect, dof)
    sigma, reason = _sigma_by_name(cov, aspect)
    return IntrinsicsSolution(
        model=m.name, image_size=size, camera_matrix=readonly(K), dist_coeffs=readonly(D),
        rms_px=float(rms), per_view_rms_px=readonly(np.asarray(per_view).ravel()),
        rvecs=readonly(rv), tvecs=readonly(tv), residuals_px=tuple(residuals),
        sigma=sigma, sigma_refused_reason=reason, n_residuals=n_res, n_parameters=n_par,
        aspect_ratio=aspect, covariance=cov, sigma_opencv=_opencv_sigma(m, std_int),
    )


def _k1k2_start(object_points_per_view: Sequence[np.ndarray], image_points_per_view: Sequence[np.ndarray],
                image_size: tuple[int, int]) -> np.ndarray | None:
    """(3, 3) K of the k1k2 solve of the same corners, the rational model's start; None when k1k2 fails."""
    try:
        return np.array(solve_intrinsics(object_points_per_view, image_points_per_view, image_size,
                                         DEFAULT_MODEL, uncertainty=False).camera_matrix)
    except (InputError, NumericalError):  # the rational solve names the problem in its own words
        return None


def is_fisheye(model: str) -> bool:
    """True for a model solved and projected by the fisheye module (name as in MODELS)."""
    return model in MODELS and MODELS[model].kind == "fisheye"


def project_points(object_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, camera_matrix: np.ndarray,
                   dist_coeffs: np.ndarray, model: str) -> np.ndarray:
    """(N, 3) board points -> (N, 2) float64 px through ``model``'s lens (pinhole or fisheye)."""
    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    if is_fisheye(model):
        return project_fisheye(obj, rvec, tvec, camera_matrix, dist_coeffs)
    return cv2.projectPoints(obj, np.asarray(rvec, np.float64), np.asarray(tvec, np.float64),
                             np.asarray(camera_matrix, np.float64), np.asarray(dist_coeffs, np.float64))[0].reshape(-1, 2)


def fit_pose(object_points: np.ndarray, image_points: np.ndarray, camera_matrix: np.ndarray,
             dist_coeffs: np.ndarray, model: str) -> tuple[np.ndarray, np.ndarray] | None:
    """T_cam_board (rvec, tvec) of one view with the lens frozen, minimising pixel residuals; None if none."""
    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    img = np.asarray(image_points, np.float64).reshape(-1, 2)
    if is_fisheye(model):
        pose = fisheye_pose(obj, img, camera_matrix, dist_coeffs)
        return None if pose is None else refine_fisheye_pose(obj, img, camera_matrix, dist_coeffs, *pose)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera_matrix, dist_coeffs, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
        return None
    return rvec.ravel(), tvec.ravel()
