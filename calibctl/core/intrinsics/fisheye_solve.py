"""Fisheye intrinsics (equidistant Kannala-Brandt, k1..k4): a self-initialising solve with honest sigma.

Why not cv2.fisheye.calibrate as is: it starts from f = max(W, H) / pi and diverges or stops in a
bad minimum when the lens is far from that, and it alternates intrinsics and poses instead of solving
them jointly, so its stopping point is not the least-squares minimum the covariance assumes. Here:

1. focal guess from per-view homographies (calibctl.core.intrinsics.fisheye_model.focal_guess_px), principal
   point at the image centre, k = 0;
2. each view's pose from cv2.solvePnP on its corners turned into pinhole rays at that guess (only
   corners within 75 deg of the axis, where the rays are well conditioned); a view whose pose cannot
   be found is named;
3. joint Levenberg-Marquardt over fx, fy, cx, cy, k1..k4 and every pose, with OpenCV's own
   projection and analytic Jacobian (cv2.fisheye.projectPoints), the poses eliminated per view by
   the Schur complement (each view's pose touches only its own rows), Marquardt-scaled damping: the
   shared solver calibctl.core.lm with this module's schedule (``DAMPING``, ``COST_TOLERANCE``);
4. covariance from the same Jacobian at the minimum (calibctl.core.intrinsics.covariance.schur_covariance).

Skew is fixed at 0 (CALIB_FIX_SKEW), fx and fy are free (the fisheye module has no aspect flag).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from calibctl.core.intrinsics.covariance import schur_covariance
from calibctl.core.intrinsics.fisheye_model import (
    fisheye_pose,
    focal_guess_px,
    project_with_jacobian,
    view_guess_rms_px,
)
from calibctl.core.intrinsics.solution import (
    MIN_SIGMA_DOF,
    DistortionModel,
    IntrinsicsSolution,
    check_inputs,
    check_output,
    readonly,
    single_threaded_opencv,
    too_few_dof_covariance,
)
from calibctl.core.lm import Damping, SchurSystem, solve_lm
from calibctl.errors import InputError, NumericalError

FISHEYE_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")
MAX_ITERATIONS = 200
# Stop when a step lowers the cost by less than this fraction (double precision leaves ~1e-16).
COST_TOLERANCE = 1e-13
DAMPING = Damping(initial=1e-3, decrease=3.0, increase=4.0, floor=1e-9, ceiling=1e8)


def _initial(
    objs: list[np.ndarray], imgs: list[np.ndarray], size: tuple[int, int], initial: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if initial is not None:
        K0 = np.asarray(initial, np.float64).reshape(3, 3)
        if not (np.isfinite(K0).all() and K0[0, 0] > 0 and K0[1, 1] > 0):
            raise InputError("the initial camera matrix must be finite with positive fx, fy")
        intr = np.array([K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2], 0.0, 0.0, 0.0, 0.0])
    else:
        f = focal_guess_px(objs, imgs, size)
        if f is None:
            rms = view_guess_rms_px(objs, imgs, size, max(size) / math.pi)
            bad = [i for i in range(len(objs)) if not np.isfinite(rms[i])]
            raise NumericalError(
                "the fisheye solve cannot be initialised: no focal length makes the views' corners fit "
                "planar boards"
                + (f" (views {bad} have fewer than 6 corners within 75 deg of the axis)" if bad else ""),
                hint="check the image size and the board geometry; capture views with the board nearer the "
                "centre",
            )
        intr = np.array([f, f, (size[0] - 1) / 2.0, (size[1] - 1) / 2.0, 0.0, 0.0, 0.0, 0.0])
    K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
    rv, tv = [], []
    for i, (o, p) in enumerate(zip(objs, imgs, strict=True)):
        pose = fisheye_pose(o, p, K, intr[4:])
        if pose is None:
            raise NumericalError(
                f"the fisheye solve cannot be initialised: view {i}'s board pose is not determined "
                f"by its corners at the initial focal length {intr[0]:.1f} px",
                hint=f"drop view {i} (its corners may be collinear or mis-ordered)",
            )
        rv.append(pose[0])
        tv.append(pose[1])
    return intr, np.array(rv), np.array(tv)


def _normal_equations(objs, imgs, intr, rv, tv):
    """Per view (J_int, J_pose, residuals) at the current parameters, and the total squared residual."""
    out, ssr = [], 0.0
    for o, p, r, t in zip(objs, imgs, rv, tv, strict=True):
        proj, J = project_with_jacobian(o, r, t, intr)
        res = (p - proj).reshape(-1)
        out.append((J[:, :8], J[:, 8:14], res))
        ssr += float(res @ res)
    return out, ssr


def _lm(objs, imgs, intr, rv, tv) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Joint Levenberg-Marquardt (calibctl.core.lm, Schur path); returns the parameters and the iterations
    used."""

    def evaluate(params: tuple[np.ndarray, np.ndarray, np.ndarray]) -> SchurSystem:
        blocks, _ = _normal_equations(objs, imgs, *params)
        return SchurSystem.from_jacobians(blocks)

    def retract(
        params: tuple[np.ndarray, np.ndarray, np.ndarray], delta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d_pose = delta[8:].reshape(-1, 6)
        return params[0] + delta[:8], params[1] + d_pose[:, :3], params[2] + d_pose[:, 3:]

    out = solve_lm(
        evaluate,
        (intr, rv, tv),
        retract,
        damping=DAMPING,
        max_iterations=MAX_ITERATIONS,
        relative_tolerance=COST_TOLERANCE,
        label="the fisheye solve",
        hint="check the image size and the board geometry; drop views whose corners are mis-ordered",
    )
    return *out.params, out.iterations


def solve_fisheye(
    object_points_per_view: Sequence[np.ndarray],
    image_points_per_view: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: DistortionModel,
    initial: np.ndarray | None = None,
) -> IntrinsicsSolution:
    """Solve fx, fy, cx, cy, k1..k4 and every view's pose (shapes as solve.solve_intrinsics).

    Raises:
        InputError: malformed input. NumericalError: no initialisation (names the view), diverged,
            or the corners are not explained (names the worst view).
    """
    size = (int(image_size[0]), int(image_size[1]))
    objs32, imgs32 = check_inputs(object_points_per_view, image_points_per_view, image_size, model)
    objs = [o.astype(np.float64) for o in objs32]
    imgs = [np.asarray(p, np.float64).reshape(-1, 2) for p in image_points_per_view]
    with single_threaded_opencv():
        intr, rv, tv = _initial(objs, imgs, size, initial)
        intr, rv, tv, _ = _lm(objs, imgs, intr, rv, tv)
        blocks, ssr = _normal_equations(objs, imgs, intr, rv, tv)
    K = np.array([[intr[0], 0.0, intr[2]], [0.0, intr[1], intr[3]], [0.0, 0.0, 1.0]])
    D = intr[4:8].copy()
    residuals = [readonly(r.reshape(-1, 2)) for _, _, r in blocks]
    per_view = np.array([math.sqrt(float(np.mean(np.sum(r**2, axis=1)))) for r in residuals])
    n_corners = sum(len(o) for o in objs)
    rms = math.sqrt(ssr / n_corners) if n_corners else float("nan")
    try:
        check_output(K, D, rms, rv, tv, size)
    except NumericalError as exc:
        worst = int(np.nanargmax(per_view)) if np.isfinite(per_view).any() else 0
        raise NumericalError(
            f"{exc.message}; the worst view is view {worst} (RMS {per_view[worst]:.2f} px)",
            hint=f"drop view {worst}, or check its corners; {exc.hint}",
        ) from exc
    n_res, n_par = 2 * n_corners, model.n_free_intrinsic_params + 6 * len(objs)
    if n_res - n_par < MIN_SIGMA_DOF:
        cov = too_few_dof_covariance(n_res, n_par)
    else:
        cov = schur_covariance(((Ji, Jp, FISHEYE_NAMES) for Ji, Jp, _ in blocks), residuals, n_res - n_par)
    sigma: dict[str, float] = {}
    reason = cov.refused_reason
    if cov.covariance is not None:
        sigma = dict(zip(cov.names, np.sqrt(np.diag(cov.covariance)).tolist(), strict=True))
    return IntrinsicsSolution(
        model=model.name,
        image_size=size,
        camera_matrix=readonly(K),
        dist_coeffs=readonly(D),
        rms_px=rms,
        per_view_rms_px=readonly(per_view),
        rvecs=readonly(rv),
        tvecs=readonly(tv),
        residuals_px=tuple(residuals),
        sigma=sigma,
        sigma_refused_reason=reason,
        n_residuals=n_res,
        n_parameters=n_par,
        aspect_ratio=None,
        covariance=cov,
    )
