"""Rig extrinsics: OpenCV's stereo solve for two cameras, a joint LM for three or more, one covariance.

Solvers
    Two cameras: cv2.stereoCalibrateExtended (CALIB_FIX_INTRINSIC, or the member's model flags with
    CALIB_USE_INTRINSIC_GUESS under ``refine_intrinsics``) on the frames both cameras saw, corners
    restricted to the ids both detected. Three or more, or any fisheye member: calibctl's joint
    Levenberg-Marquardt over every camera pose and board pose (rig_problem; a fisheye member projects
    through cv2.fisheye.projectPoints), run by the shared solver calibctl.core.lm with this module's
    schedule (``LM_DAMPING``, ``LM_RELATIVE_TOL``), each frame's board pose eliminated by the Schur
    complement (the same steps as the dense system to 1e-15 on the bench rigs; benchmarks/bench_lm.py).
    cv2.fisheye.stereoCalibrate (CALIB_FIX_INTRINSIC) on the real sourishg fisheye pair with calibctl's
    intrinsics lands on the same baseline to 1e-9 mm, but gives no covariance and cannot refine through
    calibctl's models; left to fit the lenses itself it asserts in InitExtrinsics ("fabs(norm_u1) > 0")
    on that pair. cv2.calibrateMultiview exists in the OpenCV 5.0.0
    wheel but was not usable: it re-estimates the intrinsics even under CALIB_FIX_INTRINSIC,
    refuses CALIB_USE_INTRINSIC_GUESS ("camera matrix is not 3x3" for 3x3 inputs), and on a
    seeded 3-camera synthetic rig (0.2 px noise) missed a 2.9 deg rotation by 0.25 deg.

Uncertainty (calibctl's own, like core.intrinsics.covariance does for intrinsics)
    core.extrinsics.rig_uncertainty: the Jacobian covariance (with the members' own carried in when their
    intrinsics are held fixed) and the frame-level (cluster-robust) one; per parameter the larger is reported.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from calibctl.core.blas_threads import single_threaded
from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics.rig_init import initial_poses, pair_spreads
from calibctl.core.extrinsics.rig_problem import Layout, MemberIntrinsics, RigViews, normal_equations
from calibctl.core.extrinsics.rig_tree import Edge, RigTree, T_to_pose, pose_to_T, propagate
from calibctl.core.extrinsics.rig_uncertainty import rig_covariance
from calibctl.core.extrinsics.se3 import invert
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.solve import MAX_RMS_PX, get_model, single_threaded_opencv
from calibctl.core.lm import Damping, DenseSystem, SchurSystem, solve_lm
from calibctl.errors import CalibctlError, InconsistentDataError, NumericalError

MAX_LM_ITERATIONS = 100
LM_RELATIVE_TOL = 1e-12  # stop when one accepted step lowers the residual sum by less than this share
LM_DAMPING = Damping(initial=1e-3, decrease=10.0, increase=10.0, floor=1e-12, ceiling=1e12)
MIN_SHARED_CORNERS = 6
"""A pair's frame counts when both cameras saw at least this many of the same corners (as many as a ChArUco
view needs, core.capture.detect.CHARUCO_MIN_CORNERS). Four coplanar corners leave PnP ambiguous: on
caliscope-4cam one frame of the pair 1-2 with 4 shared corners put the board 0.11 m from both cameras instead
of 0.8-0.9 m (their full views: 0.28 / 0.15 px), and the pair's stereo solve diverged to 37 px; without that
frame, 1.07 / 1.23 px."""
STEREO_CRITERIA = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)


@dataclass(frozen=True)
class RigSolution:
    """A solved rig.

    Attributes:
        views: the synchronised views used (frames seen by at least two cameras).
        members: each camera's intrinsics after the solve (unchanged unless refined).
        cam_poses: (C, 6) pose vectors of T_cam_root (row 0, the root, is zero).
        board_poses: (F, 6) pose vectors of T_root_board per frame.
        covariance: (6(C-1), 6(C-1)) covariance of cam_poses[1:], flattened: the reported one (per parameter
            the larger of the Jacobian and the frame-level one, core.extrinsics.rig_uncertainty).
        tree: T_root_cam edges with each camera's 6x6 pose covariance.
        rms_px: per camera fit RMS (OpenCV's per-corner 2-D definition).
        solver: "cv2.stereoCalibrateExtended" or "calibctl joint LM".
        refine_intrinsics: whether intrinsics were free.
        residual_variance_px2: s^2 per coordinate.
        jacobian_covariance: same shape, the Jacobian one alone (None: same as ``covariance``).
        frame_factors: (6(C-1),) frame-level sigma / Jacobian sigma per parameter, None under
            rig_uncertainty.MIN_FRAMES clusters. frame_clusters: the clusters it was summed over.
    """

    views: RigViews
    members: tuple[MemberIntrinsics, ...]
    cam_poses: np.ndarray
    board_poses: np.ndarray
    covariance: np.ndarray
    tree: RigTree
    rms_px: tuple[float, ...]
    solver: str
    refine_intrinsics: bool
    residual_variance_px2: float
    jacobian_covariance: np.ndarray | None = None
    frame_factors: np.ndarray | None = None
    frame_clusters: int = 0

    def T_cam_root(self, c: int) -> np.ndarray:
        return pose_to_T(self.cam_poses[c])

    def T_a_b(self, a: int, b: int) -> np.ndarray:
        """(4, 4) T_a_b between cameras a and b (indices)."""
        return self.T_cam_root(a) @ invert(self.T_cam_root(b))

    def pair_covariance(self, a: int, b: int, jacobian: bool = False) -> np.ndarray:
        """(6, 6) covariance of the pose vector of T_a_b (cross terms of the joint solve included); the
        reported one, or the Jacobian one alone under ``jacobian``."""
        cams = [c for c in (a, b) if c > 0]
        idx = [6 * (c - 1) + k for c in cams for k in range(6)]

        def fn(x: np.ndarray) -> np.ndarray:
            poses = iter(np.split(x, len(cams)))
            Ta = pose_to_T(next(poses)) if a > 0 else np.eye(4)
            Tb = pose_to_T(next(poses)) if b > 0 else np.eye(4)
            return T_to_pose(Ta @ invert(Tb))

        x = np.concatenate([self.cam_poses[c] for c in cams])
        full = (
            self.jacobian_covariance if jacobian and self.jacobian_covariance is not None else self.covariance
        )
        return propagate(fn, x, full[np.ix_(idx, idx)])


def shared_corners_only(views: RigViews) -> RigViews:
    """Frames seen by >= 2 cameras; for two cameras, each view cut to the corner ids both detected."""
    rows, names = [], []
    for name, row in zip(views.frames, views.views, strict=True):
        seen = [v for v in row if v is not None]
        if len(seen) < 2:
            continue
        if len(row) == 2 and row[0] is not None and row[1] is not None:
            common = np.intersect1d(row[0].corner_ids, row[1].corner_ids)
            if common.size < MIN_SHARED_CORNERS:
                continue
            row = (_select(row[0], common), _select(row[1], common))
        rows.append(row)
        names.append(name)
    return RigViews(views.cameras, views.model_points_m, tuple(names), tuple(rows))


def _select(view: BoardView, ids: np.ndarray) -> BoardView:
    order = {int(i): k for k, i in enumerate(view.corner_ids)}
    return BoardView(view.name, ids, view.corners_px[[order[int(i)] for i in ids]])


def _stereo(
    views: RigViews, members: Sequence[MemberIntrinsics], refine: bool, model_flags: int
) -> tuple[np.ndarray, np.ndarray, list[MemberIntrinsics]]:
    pairs = [(v[0], v[1]) for v in views.views if v[0] is not None and v[1] is not None]
    obj = [va.object_points(views.model_points_m).astype(np.float32) for va, _ in pairs]
    img = [[pair[c].corners_px.astype(np.float32) for pair in pairs] for c in (0, 1)]
    m0, m1 = members
    flags = (model_flags | cv2.CALIB_USE_INTRINSIC_GUESS) if refine else cv2.CALIB_FIX_INTRINSIC
    start = [
        np.array(a, dtype=np.float64)
        for a in (m0.camera_matrix, m0.dist_coeffs, m1.camera_matrix, m1.dist_coeffs)
    ]
    if max(start[1].size, start[3].size) >= 8:  # rational members: without the flag OpenCV drops k4..k6 (and
        flags |= cv2.CALIB_RATIONAL_MODEL  # returns 5 coefficients the rig's Jacobian cannot index)
    with single_threaded_opencv():
        out = cv2.stereoCalibrateExtended(
            obj,
            img[0],
            img[1],
            start[0],
            start[1],
            start[2],
            start[3],
            m0.image_size,
            np.eye(3),
            np.zeros((3, 1)),
            flags=flags,
            criteria=STEREO_CRITERIA,
        )
    K1, D1, K2, D2, R, T = out[1:7]
    rvecs, tvecs = out[9], out[10]
    cam_poses = np.zeros((2, 6))
    cam_poses[1] = np.concatenate([cv2.Rodrigues(R)[0].ravel(), np.asarray(T).ravel()])
    board = np.array([np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in zip(rvecs, tvecs, strict=True)])
    new = [
        replace(m, camera_matrix=np.asarray(K), dist_coeffs=np.asarray(D).ravel())
        for m, K, D in ((m0, K1, D1), (m1, K2, D2))
    ]
    return cam_poses, board, new


def _lm(
    views: RigViews,
    members: list[MemberIntrinsics],
    cam_poses: np.ndarray,
    board_poses: np.ndarray,
    refine: bool,
) -> tuple[np.ndarray, np.ndarray, list[MemberIntrinsics]]:
    """calibctl.core.lm over the free parameters, each frame's board pose eliminated (Schur path): a board
    pose touches only its own frame's rows, so a frame's block couples only with the camera poses and
    intrinsics, never with another frame's."""
    layout = Layout(len(views.cameras), len(views.frames), tuple(m.n_params for m in members))
    board_idx = layout.board0 + np.arange(6 * layout.n_frames).reshape(-1, 6)
    shared = np.concatenate(
        [
            np.arange(layout.board0),
            np.arange(layout.board0 + 6 * layout.n_frames, layout.size) if refine else np.arange(0),
        ]
    )
    Params = tuple[np.ndarray, np.ndarray, list[MemberIntrinsics]]

    def evaluate(params: Params) -> SchurSystem:
        ne = normal_equations(views, params[2], params[0], params[1], layout)
        return SchurSystem.from_dense(DenseSystem(ne.ssr, ne.H, ne.g), shared, board_idx)

    def retract(params: Params, delta: np.ndarray) -> Params:
        step = np.zeros(layout.size)
        step[shared], step[board_idx.ravel()] = delta[: shared.size], delta[shared.size :]
        cam = params[0].copy()
        cam[1:] += step[: layout.board0].reshape(-1, 6)
        board = params[1] + step[layout.board0 : layout.board0 + 6 * layout.n_frames].reshape(-1, 6)
        return cam, board, [m.stepped(step[layout.intrinsics(c)]) for c, m in enumerate(params[2])]

    out = solve_lm(
        evaluate,
        (cam_poses, board_poses, members),
        retract,
        damping=LM_DAMPING,
        max_iterations=MAX_LM_ITERATIONS,
        relative_tolerance=LM_RELATIVE_TOL,
        label="the rig solve",
        hint="check that every camera's intrinsics belong to it and the board is right",
    )
    return out.params


def _tree(names: Sequence[str], cam_poses: np.ndarray, cov: np.ndarray) -> RigTree:
    edges = []
    for c in range(1, len(names)):
        block = cov[6 * (c - 1) : 6 * c, 6 * (c - 1) : 6 * c]
        edge_cov = propagate(lambda p: T_to_pose(invert(pose_to_T(p))), cam_poses[c], block)
        edges.append(Edge(names[0], names[c], invert(pose_to_T(cam_poses[c])), edge_cov))
    return RigTree(names[0], tuple(edges))


RIGID_HINT = (
    "the cameras must not move against each other and the board must be still while a frame is taken; "
    "check the sources are synchronised and each camera's calibration belongs to it"
)


def diverged(views: RigViews, members: Sequence[MemberIntrinsics], worst_rms_px: float) -> CalibctlError:
    """The error for a solve that leaves more than MAX_RMS_PX: InconsistentDataError (a verdict, exit 1)
    when a pair's frames contradict each other whatever the solver does (no frame's own relative pose
    carries the board into the other camera within MAX_RMS_PX: rig_init.pair_spreads); NumericalError
    (could not run, exit 2) when they agree, or when too few frames fit their own camera to tell."""
    spreads = pair_spreads(views, members)
    words = "; ".join(s.words(views.cameras) for s in spreads)
    apart = [s for s in spreads if not s.transfer_rms_px <= MAX_RMS_PX]
    if apart:
        pairs = ", ".join(f"{views.cameras[s.a]}-{views.cameras[s.b]}" for s in apart)
        return InconsistentDataError(
            "the rig's frames contradict each other, so the cameras were not rigid or not synchronised: "
            "the solve "
            f"leaves RMS {worst_rms_px:.2f} px (limit {MAX_RMS_PX:.0f} px) and no frame's own pose of "
            f"{pairs} fits "
            f"the other frames within {MAX_RMS_PX:.0f} px; {words}",
            hint=RIGID_HINT,
        )
    agree = f"; the frames agree with one rigid rig ({words})" if spreads else ""
    return NumericalError(
        f"the rig solve diverged: RMS {worst_rms_px:.2f} px (limit {MAX_RMS_PX:.0f} px){agree}",
        hint=RIGID_HINT
        if not spreads
        else "the solver failed on frames that agree: check that "
        "each camera's calibration belongs to it, and report the photos if it does",
    )


def solve_rig(
    views: RigViews,
    members: Sequence[MemberIntrinsics],
    refine_intrinsics: bool = False,
    model: str = DEFAULT_MODEL,
    solver: str = "auto",
) -> RigSolution:
    """Solve the extrinsics of a rig (cameras[0] is the root).

    Args:
        views: synchronised views; frames seen by fewer than two cameras are left out.
        members: per camera intrinsics, same order as views.cameras.
        refine_intrinsics: free each member's model parameters too.
        model: the members' solve model (core.intrinsics.solve.MODELS) whose flags a refining stereo solve
        uses. solver: "auto" (OpenCV stereo for two cameras, joint LM otherwise), "opencv" or "lm".

    Raises:
        NumericalError: too few shared views, unobservable, or diverged on frames that agree.
        InconsistentDataError: diverged because the frames contradict each other (``diverged``).
    """
    with single_threaded():  # OpenCV and BLAS on one thread: the LM is serial, spare threads only spin
        return _solve_rig(views, members, refine_intrinsics, model, solver)


def _solve_rig(
    views: RigViews, members: Sequence[MemberIntrinsics], refine_intrinsics: bool, model: str, solver: str
) -> RigSolution:
    for m in members:  # refused up front: where NaN intrinsics would fail later depends on the OpenCV version
        if not (np.isfinite(m.camera_matrix).all() and np.isfinite(m.dist_coeffs).all()):
            raise NumericalError(
                f"the rig solve cannot start: camera {m.name}'s intrinsics are NaN or infinite",
                hint="check that every camera's intrinsics belong to it (re-solve that camera)",
            )
    views = shared_corners_only(views)
    if len(views.frames) < 2:
        raise NumericalError(
            f"only {len(views.frames)} frame(s) show the board to two cameras at once",
            hint="capture views that at least two cameras see together",
        )
    members = list(members)
    pinhole = all(m.lens != "fisheye" for m in members)  # cv2.stereoCalibrateExtended knows no fisheye lens
    use_opencv = pinhole and (solver == "opencv" or (solver == "auto" and len(views.cameras) == 2))
    if use_opencv and len(views.cameras) == 2:
        cam_poses, board_poses, members = _stereo(views, members, refine_intrinsics, get_model(model).flags)
        name = "cv2.stereoCalibrateExtended"
    else:
        cam_poses, board_poses = initial_poses(views, members)
        cam_poses, board_poses, members = _lm(views, members, cam_poses, board_poses, refine_intrinsics)
        name = "calibctl joint LM"
    if not (np.isfinite(cam_poses).all() and np.isfinite(board_poses).all()):
        raise NumericalError(
            "the rig solve returned NaN or infinite values",
            hint="check that every camera's intrinsics belong to it and the board is right",
        )
    unc = rig_covariance(views, members, cam_poses, board_poses, refine_intrinsics)
    cov, ne = unc.covariance, unc.normal_equations
    rms = []
    for c in range(len(views.cameras)):
        res = [r for (_, cc), r in ne.residuals_px.items() if cc == c]
        rms.append(float(np.sqrt(np.mean(np.sum(np.vstack(res) ** 2, axis=1)))) if res else float("nan"))
    worst = max(r for r in rms if np.isfinite(r)) if any(np.isfinite(rms)) else float("nan")
    if not worst <= MAX_RMS_PX:
        raise diverged(views, members, worst)
    tree = _tree(views.cameras, cam_poses, cov)
    return RigSolution(
        views,
        tuple(members),
        cam_poses,
        board_poses,
        cov,
        tree,
        tuple(rms),
        name,
        refine_intrinsics,
        unc.residual_variance_px2,
        unc.jacobian,
        unc.factors,
        unc.clusters,
    )
