"""Intrinsic calibration: cv2.calibrateCameraExtended on stored corners, with honest uncertainty.

Units and conventions: pixels with the top-left pixel's centre at (0, 0) (OpenCV), model points in
the board frame in metres (any unit works: only ``tvecs`` carry it), distortion in OpenCV order
``k1, k2, p1, p2, k3[, k4, k5, k6]`` applied in normalised coordinates.

``rms_px`` is OpenCV's definition: sqrt(sum over corners of the squared 2-D residual / number of
corners), i.e. a per-corner RMS, not per coordinate (per coordinate is rms_px / sqrt(2)).

Uncertainty
    sigma comes from calibctl.core.intrinsics.covariance (Jacobian at the solution, poses eliminated by the
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
    model can stop in a bad minimum on a wide lens: on a 190 deg circular render
    (tests/core/intrinsics/test_solve.py) RMS 4.39 px against 0.276 px from a warm start. Without an
    ``initial`` K it therefore starts from the k1k2 solution's K (CALIB_USE_INTRINSIC_GUESS); where k1k2
    itself cannot be solved it starts cold. On opencv-left-right, udacity-camcal and 120-170 deg renders the
    warm and the cold start reach the same minimum (RMS equal to 1e-3 px).

Determinism
    OpenCV parallelises parts of the solve; with 2+ threads the summation order varies and the
    same input gives results differing around 1e-10 px. The solve runs with cv2.setNumThreads(1)
    (restored afterwards), which makes it bit-identical run to run.

Solves asked twice
    A solve of the same corners, model and start is therefore the same solve, and ``calibrate`` asks for it
    twice:
    the capture's projection gate solves the session, then the solve's corner rule starts from the same
    solve of the same corners (on a lens the tilt's small model cannot explain, the tilt lens is the same
    fisheye solve the gate asks for, core.capture.tilt); ``--model auto`` asks its ladder again, its rational
    folds start from the k1k2 fit of the same fold, and the chosen model's validation refits the folds the
    ladder fitted. The last RECENT_SOLVES solves with uncertainty and RECENT_FITS without, of a named model,
    are remembered by a digest of their inputs (``core.intrinsics.recent_answers``): the second ask costs a
    digest, and its answer is the first one's, number for number (tests/core/intrinsics/test_solve_reuse.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from calibctl.core.intrinsics.covariance import IntrinsicCovariance, intrinsic_covariance
from calibctl.core.intrinsics.fisheye_model import (
    fisheye_pose,
    forget_view_scores,
    project_fisheye,
    refine_fisheye_pose,
)
from calibctl.core.intrinsics.fisheye_solve import solve_fisheye
from calibctl.core.intrinsics.recent_answers import RecentAnswers, values_digest
from calibctl.core.intrinsics.solution import (
    CALIB_FIX_SKEW,
    CALIB_RECOMPUTE_EXTRINSIC,
    DEFAULT_MODEL,
    DISTORTION_NAMES,
    FISHEYE_DIST_NAMES,
    MAX_RMS_PX,
    MIN_CORNERS_PER_VIEW,
    MIN_FOCAL_FRAC,
    MIN_SIGMA_DOF,
    MODELS,
    NO_UNCERTAINTY,
    WARM_CRITERIA,
    DistortionModel,
    IntrinsicsSolution,
    check_inputs,
    check_output,
    get_model,
    parameter_count,
    readonly,
    residual_rms_px,
    single_threaded_opencv,
    too_few_dof_covariance,
)
from calibctl.errors import InputError, NumericalError

# The solve API: the solver and its vocabulary from ``solution`` (callers import both from here).
__all__ = [
    "CALIB_FIX_SKEW",
    "CALIB_RECOMPUTE_EXTRINSIC",
    "DEFAULT_MODEL",
    "DISTORTION_NAMES",
    "DistortionModel",
    "FISHEYE_DIST_NAMES",
    "IntrinsicsSolution",
    "MAX_RMS_PX",
    "MIN_CORNERS_PER_VIEW",
    "MIN_FOCAL_FRAC",
    "MIN_SIGMA_DOF",
    "MODELS",
    "NO_UNCERTAINTY",
    "check_inputs",
    "check_output",
    "get_model",
    "parameter_count",
    "readonly",
    "residual_rms_px",
    "single_threaded_opencv",
    "solve_intrinsics",
    "starts_warm",
    "is_fisheye",
    "project_points",
    "fit_pose",
    "forget_recent_solves",
]

# Index of each parameter in OpenCV's stdDeviationsIntrinsics (and in the distortion vector + 4).
_STD_INDEX = {
    "fx": 0,
    "fy": 1,
    "cx": 2,
    "cy": 3,
    "k1": 4,
    "k2": 5,
    "p1": 6,
    "p2": 7,
    "k3": 8,
    "k4": 9,
    "k5": 10,
    "k6": 11,
}


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


# Remembered solves (module docstring), apart by kind so that folds never push out a session's solve: the
# solves with uncertainty (a session's, once per model), and the fits without (folds, groups), enough for
# --model auto's whole ladder between its k1k2 folds and the chosen model's validation of the same folds. An
# 86-view k1k2 solution holds 79 KB of arrays (residuals, poses, covariance): ~6 MB at most at that size.
RECENT_SOLVES = 8
RECENT_FITS = 64
_RECENT: RecentAnswers[IntrinsicsSolution] = RecentAnswers(RECENT_SOLVES)
_RECENT_FITS: RecentAnswers[IntrinsicsSolution] = RecentAnswers(RECENT_FITS)


def forget_recent_solves() -> None:
    """Forget the remembered solves (and the fisheye focal guess's view scores,
    core.intrinsics.fisheye_model): a benchmark that times the same solve again must compute it again."""
    _RECENT.clear()
    _RECENT_FITS.clear()
    forget_view_scores()


def solve_intrinsics(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: str | DistortionModel = DEFAULT_MODEL,
    initial: np.ndarray | None = None,
    uncertainty: bool = True,
    initial_dist: np.ndarray | None = None,
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
        initial_dist: optional distortion guess (the model's coefficients, OpenCV order), used with
            ``initial`` only: a warm start from a solve of more of the same views, stopped at a relative step
            (``solution.WARM_CRITERIA``) instead of OpenCV's DBL_EPSILON. Fisheye models ignore it.

    Raises:
        InputError: malformed, non-finite, or out-of-image input.
        NumericalError: too few views/corners for the model; OpenCV failed; diverged/non-finite output.
        UsageError: unknown model name.
    """
    m = get_model(model) if isinstance(model, str) else model
    fisheye = m.kind == "fisheye"
    if m is MODELS.get(m.name):  # a named model: its name says what it solves
        try:
            key = values_digest(
                object_points_per_view,
                image_points_per_view,
                tuple(int(v) for v in image_size),
                m.name,
                fisheye or uncertainty,  # a fisheye solve always has its uncertainty
                None if initial is None else np.asarray(initial, np.float64).tobytes(),
                None
                if initial is None or initial_dist is None
                else np.asarray(initial_dist, np.float64).tobytes(),
            )
        except (TypeError, ValueError):  # malformed input: the solve names the problem in its own words
            key = None
        if key is not None:
            recent = _RECENT if fisheye or uncertainty else _RECENT_FITS
            return recent.answer(
                key,
                lambda: _solve(
                    object_points_per_view,
                    image_points_per_view,
                    image_size,
                    m,
                    initial,
                    uncertainty,
                    initial_dist,
                ),
            )
    return _solve(
        object_points_per_view, image_points_per_view, image_size, m, initial, uncertainty, initial_dist
    )


def _solve(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    m: DistortionModel,
    initial: np.ndarray | None,
    uncertainty: bool,
    initial_dist: np.ndarray | None = None,
) -> IntrinsicsSolution:
    """``solve_intrinsics`` of a resolved model, computed (never remembered)."""
    if m.kind == "fisheye":
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
    stop: dict[str, Any] = {}  # a cold start: OpenCV's own criteria
    if initial is not None and initial_dist is not None:
        guess = np.asarray(initial_dist, dtype=np.float64).ravel()
        if guess.size != m.n_coeffs or not np.isfinite(guess).all():
            raise InputError(f"the initial distortion must be {m.n_coeffs} finite coefficients for {m.name}")
        D0 = guess.copy()
        stop["criteria"] = WARM_CRITERIA
    try:
        with single_threaded_opencv():
            if uncertainty:
                rms, K, D, rvecs, tvecs, std_int, _std_ext, per_view = cv2.calibrateCameraExtended(
                    objs, imgs, size, K0.copy(), D0.copy(), flags=flags, **stop
                )
            else:
                rms, K, D, rvecs, tvecs = cv2.calibrateCamera(
                    objs, imgs, size, K0.copy(), D0.copy(), flags=flags, **stop
                )
    except cv2.error as exc:
        detail = str(exc).strip().splitlines()[-1].split(" error: ")[-1]
        raise NumericalError(
            f"OpenCV could not solve model {m.name}: {detail}",
            hint="check that every view is a planar board with distinct corners",
        ) from exc
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
            model=m.name,
            image_size=size,
            camera_matrix=readonly(K),
            dist_coeffs=readonly(D),
            rms_px=float(rms),
            per_view_rms_px=readonly(np.array([residual_rms_px(r) for r in residuals])),
            rvecs=readonly(rv),
            tvecs=readonly(tv),
            residuals_px=tuple(residuals),
            sigma_refused_reason=NO_UNCERTAINTY,
            n_residuals=n_res,
            n_parameters=n_par,
            aspect_ratio=aspect,
        )
    if dof < MIN_SIGMA_DOF:
        cov = too_few_dof_covariance(n_res, n_par)
    else:
        cov = intrinsic_covariance(
            [o.astype(np.float64) for o in objs],
            rv,
            tv,
            K,
            D,
            residuals,
            m.free_intrinsics,
            m.free_distortion,
            aspect,
            dof,
        )
    sigma, reason = _sigma_by_name(cov, aspect)
    return IntrinsicsSolution(
        model=m.name,
        image_size=size,
        camera_matrix=readonly(K),
        dist_coeffs=readonly(D),
        rms_px=float(rms),
        per_view_rms_px=readonly(np.asarray(per_view).ravel()),
        rvecs=readonly(rv),
        tvecs=readonly(tv),
        residuals_px=tuple(residuals),
        sigma=sigma,
        sigma_refused_reason=reason,
        n_residuals=n_res,
        n_parameters=n_par,
        aspect_ratio=aspect,
        covariance=cov,
        sigma_opencv=_opencv_sigma(m, std_int),
    )


def starts_warm(model: str) -> bool:
    """Whether a solve of part of a session's views under ``model`` may start from the whole session's K and
    distortion (``solve_intrinsics(initial=, initial_dist=)``) and land on the minimum a cold start finds.
    Measured on 16 rendered sessions (benchmarks/bench_warm_folds.py): the folds of k1k2, k1k2k3,
    k1k2p1p2k3 and opencv-default agree with their cold folds to 1.4e-8 relative; rational folds moved by up
    to 19 % (its valley is flat and has several minima; see "Initial guess of the rational model"), and a
    fisheye solve has its own start."""
    m = get_model(model)
    return m.kind != "fisheye" and not m.flags & cv2.CALIB_RATIONAL_MODEL


def _k1k2_start(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
) -> np.ndarray | None:
    """(3, 3) K of the k1k2 solve of the same corners, the rational model's start; None when k1k2 fails."""
    try:
        return np.array(
            solve_intrinsics(
                object_points_per_view, image_points_per_view, image_size, DEFAULT_MODEL, uncertainty=False
            ).camera_matrix
        )
    except (InputError, NumericalError):  # the rational solve names the problem in its own words
        return None


def is_fisheye(model: str) -> bool:
    """True for a model solved and projected by the fisheye module (name as in MODELS)."""
    return model in MODELS and MODELS[model].kind == "fisheye"


def project_points(
    object_points: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str,
) -> np.ndarray:
    """(N, 3) board points -> (N, 2) float64 px through ``model``'s lens (pinhole or fisheye)."""
    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    if is_fisheye(model):
        return project_fisheye(obj, rvec, tvec, camera_matrix, dist_coeffs)
    return cv2.projectPoints(
        obj,
        np.asarray(rvec, np.float64),
        np.asarray(tvec, np.float64),
        np.asarray(camera_matrix, np.float64),
        np.asarray(dist_coeffs, np.float64),
    )[0].reshape(-1, 2)


def fit_pose(
    object_points: np.ndarray,
    image_points: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    model: str,
) -> tuple[np.ndarray, np.ndarray] | None:
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
