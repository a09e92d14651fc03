"""The joint least-squares problem of a camera rig: data, parameter layout, normal equations.

Unknowns: ``T_cam_root`` of every camera but the root (6 each: rvec rad, tvec m), ``T_root_board``
of every synchronised frame (6 each), and each camera's intrinsics in its own solve model's
parameterisation (free or held fixed). The residual of camera c in frame f is
``observed - project(K_c, dist_c, T_cam_root_c @ T_root_board_f @ X)`` per corner, px.

The Jacobian is analytic: cv2.projectPoints gives d(px)/d(rvec, tvec of T_cam_board) and d(px)/d
intrinsics, cv2.composeRT the derivatives of the composition with respect to both factors. Normal
equations are accumulated per observation block, so memory grows with parameters, not corners.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from calibctl.core.board.views import BoardView
from calibctl.core.intrinsics.covariance import intrinsic_columns
from calibctl.core.intrinsics.solve import DISTORTION_NAMES, FISHEYE_DIST_NAMES

_K_INDEX = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}


@dataclass(frozen=True)
class MemberIntrinsics:
    """One rig member's camera model, as its own calibration left it.

    Attributes:
        name: the camera's frame name (its serial).
        camera_matrix: (3, 3) float64 K, px. dist_coeffs: (n,) float64, OpenCV order.
        image_size: (width, height) px the corners are detected at.
        free_intrinsics, free_distortion: the solve model's free parameter names
        (core.intrinsics.solve.MODELS).
        aspect: fx / fy held fixed by the model, or None.
        covariance: (p, p) covariance of those free parameters in ``intrinsic_columns`` order (px^2,
            unitless^2), or None when unknown (then fixed intrinsics are treated as exact).
        lens: "pinhole" (cv2.projectPoints, OpenCV's distortion order) or "fisheye" (the equidistant
            Kannala-Brandt lens of cv2.fisheye: dist_coeffs are k1..k4).
        jacobian_covariance: (p, p) the Jacobian covariance alone when ``covariance`` was inflated by the
            view-level rule (core.intrinsics.covariance), else None (then ``covariance`` is it).
        view_influences: view name -> (p,) that view's first-order pull on the free parameters
            (IntrinsicCovariance.view_influences), when the member was calibrated on photos the rig also
            uses; the rig's frame-level covariance then carries the member's error frame by frame.
    """

    name: str
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    free_intrinsics: tuple[str, ...] = ("fx", "fy", "cx", "cy")
    free_distortion: tuple[str, ...] = ("k1", "k2")
    aspect: float | None = 1.0
    covariance: np.ndarray | None = None
    lens: str = "pinhole"
    jacobian_covariance: np.ndarray | None = None
    view_influences: Mapping[str, np.ndarray] | None = None

    @property
    def distortion_order(self) -> tuple[str, ...]:
        """Names of dist_coeffs in order."""
        return FISHEYE_DIST_NAMES if self.lens == "fisheye" else DISTORTION_NAMES

    @property
    def n_params(self) -> int:
        return len(self.free_intrinsics) - int(self.aspect is not None) + len(self.free_distortion)

    def stepped(self, delta: np.ndarray) -> MemberIntrinsics:
        """A copy with ``delta`` (in ``intrinsic_columns`` order) added to the free parameters."""
        K = np.array(self.camera_matrix, dtype=np.float64)
        dist = np.array(self.dist_coeffs, dtype=np.float64).reshape(-1)
        i = 0
        for name in self.free_intrinsics:
            if name == "fx" and self.aspect is not None:
                continue
            if name == "fy" and self.aspect is not None:
                K[1, 1] += delta[i]
                K[0, 0] = self.aspect * K[1, 1]
            else:
                K[_K_INDEX[name]] += delta[i]
            i += 1
        for name in self.free_distortion:
            dist[self.distortion_order.index(name)] += delta[i]
            i += 1
        return replace(self, camera_matrix=K, dist_coeffs=dist)


@dataclass(frozen=True)
class RigViews:
    """Synchronised board views of a rig.

    Attributes:
        cameras: camera frame names; cameras[0] is the root.
        model_points_m: (M, 3) float64 board model points, board frame, metres.
        frames: names of the synchronised frames (a shared file-name stem or timestamp).
        views: per frame, per camera, the BoardView or None when that camera missed the board.
    """

    cameras: tuple[str, ...]
    model_points_m: np.ndarray
    frames: tuple[str, ...]
    views: tuple[tuple[BoardView | None, ...], ...]

    def subset(self, frame_indices: Sequence[int]) -> RigViews:
        idx = list(frame_indices)
        return RigViews(
            self.cameras,
            self.model_points_m,
            tuple(self.frames[i] for i in idx),
            tuple(self.views[i] for i in idx),
        )

    def shared_view_counts(self) -> dict[tuple[int, int], int]:
        """Frames in which both cameras of each pair (a < b) saw the board."""
        n = len(self.cameras)
        return {
            (a, b): sum(1 for row in self.views if row[a] is not None and row[b] is not None)
            for a in range(n)
            for b in range(a + 1, n)
        }


@dataclass
class Layout:
    """Where each unknown sits in the parameter vector."""

    n_cameras: int
    n_frames: int
    intrinsic_sizes: tuple[int, ...]
    ext0: int = field(init=False)
    board0: int = field(init=False)
    int0: tuple[int, ...] = field(init=False)
    size: int = field(init=False)

    def __post_init__(self) -> None:
        self.ext0 = 0
        self.board0 = 6 * (self.n_cameras - 1)
        starts, at = [], self.board0 + 6 * self.n_frames
        for p in self.intrinsic_sizes:
            starts.append(at)
            at += p
        self.int0 = tuple(starts)
        self.size = at

    def ext(self, c: int) -> np.ndarray:
        return np.arange(6 * (c - 1), 6 * c) if c > 0 else np.arange(0)

    def board(self, f: int) -> np.ndarray:
        return np.arange(self.board0 + 6 * f, self.board0 + 6 * f + 6)

    def intrinsics(self, c: int) -> np.ndarray:
        return np.arange(self.int0[c], self.int0[c] + self.intrinsic_sizes[c])

    def shared_index(self, idx: np.ndarray) -> np.ndarray:
        """Indices of camera-pose or intrinsic unknowns among the non-board ones (board poses left out)."""
        return np.where(idx < self.board0, idx, idx - 6 * self.n_frames)


@dataclass(frozen=True)
class NormalEquations:
    """H = J^T J, g = J^T r over all observations, with the residual sum and counts."""

    H: np.ndarray
    g: np.ndarray
    ssr: float
    n_residuals: int
    residuals_px: dict[tuple[int, int], np.ndarray]  # (frame, camera) -> (N, 2) observed - projected
    frame_scores: np.ndarray | None = None  # (F, size) J_f^T r_f per frame: g is their sum
    frame_shared_H: np.ndarray | None = None  # (F, n, n) frame f's share of H over the non-board unknowns


def project_member(
    obj: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, member: MemberIntrinsics
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 1, 2) px of (N, 3) board points at T_cam_board (rvec, tvec) through the member's lens, and the
    (2N, 10 + d) Jacobian in cv2.projectPoints' column order [rvec tvec fx fy cx cy dist...], distortion
    columns in ``member.distortion_order`` (cv2.fisheye.projectPoints' [fx fy cx cy k1..k4 rvec tvec alpha]
    rearranged)."""
    if member.lens != "fisheye":
        proj, J = cv2.projectPoints(obj, rvec, tvec, member.camera_matrix, member.dist_coeffs)
        return proj, J
    D = np.asarray(member.dist_coeffs, np.float64).reshape(-1)[:4]
    proj, J = cv2.fisheye.projectPoints(
        np.asarray(obj, np.float64).reshape(-1, 1, 3),
        np.asarray(rvec, np.float64).reshape(3, 1),
        np.asarray(tvec, np.float64).reshape(3, 1),
        member.camera_matrix,
        D,
    )
    return proj, np.hstack([J[:, 8:14], J[:, 0:8]])


def observation_jacobian(
    obj: np.ndarray, pose_cam_root: np.ndarray | None, pose_root_board: np.ndarray, member: MemberIntrinsics
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """Projection of one (frame, camera) and its Jacobian blocks.

    Returns:
        projected (N, 2) px; d/d board pose (2N, 6); d/d camera pose (2N, 6) or None for the root;
        d/d free intrinsics (2N, p).
    """
    rb, tb = pose_root_board[:3].reshape(3, 1), pose_root_board[3:].reshape(3, 1)
    if pose_cam_root is None:
        r3, t3 = rb, tb
    else:
        rc, tc = pose_cam_root[:3].reshape(3, 1), pose_cam_root[3:].reshape(3, 1)
        r3, t3, dr3dr1, _, dr3dr2, _, dt3dr1, dt3dt1, dt3dr2, dt3dt2 = cv2.composeRT(rb, tb, rc, tc)
    proj, J = project_member(obj, r3, t3, member)
    J_int, _ = intrinsic_columns(
        J, member.free_intrinsics, member.free_distortion, member.aspect, member.distortion_order
    )
    if pose_cam_root is None:
        return proj.reshape(-1, 2), J[:, :6], None, J_int
    d_r3, d_t3 = J[:, :3], J[:, 3:6]
    J_board = np.hstack([d_r3 @ dr3dr1 + d_t3 @ dt3dr1, d_t3 @ dt3dt1])
    J_cam = np.hstack([d_r3 @ dr3dr2 + d_t3 @ dt3dr2, d_t3 @ dt3dt2])
    return proj.reshape(-1, 2), J_board, J_cam, J_int


def normal_equations(
    views: RigViews,
    members: Sequence[MemberIntrinsics],
    cam_poses: np.ndarray,
    board_poses: np.ndarray,
    layout: Layout,
    per_frame: bool = False,
) -> NormalEquations:
    """Accumulate J^T J and J^T r at (cam_poses (C, 6) with row 0 unused, board_poses (F, 6)); ``per_frame``:
    each frame's share of H over the non-board unknowns too (the frame-level covariance needs it, the LM
    not)."""
    H = np.zeros((layout.size, layout.size))
    g_f = np.zeros((layout.n_frames, layout.size))
    shared = layout.size - 6 * layout.n_frames
    H_f = np.zeros((layout.n_frames, shared, shared) if per_frame else (0, 0, 0))
    ssr, n_res = 0.0, 0
    residuals: dict[tuple[int, int], np.ndarray] = {}
    for f, row in enumerate(views.views):
        for c, view in enumerate(row):
            if view is None:
                continue
            obj = view.object_points(views.model_points_m)
            proj, J_board, J_cam, J_int = observation_jacobian(
                obj, cam_poses[c] if c > 0 else None, board_poses[f], members[c]
            )
            res = view.corners_px - proj
            residuals[(f, c)] = res
            r = res.reshape(-1)
            blocks = [(layout.board(f), J_board), (layout.intrinsics(c), J_int)]
            if J_cam is not None:
                blocks.append((layout.ext(c), J_cam))
            for idx_a, Ja in blocks:
                g_f[f, idx_a] += Ja.T @ r
                for idx_b, Jb in blocks:
                    H[np.ix_(idx_a, idx_b)] += Ja.T @ Jb
            own = [(layout.shared_index(i), J) for i, J in blocks[1:]] if per_frame else []
            for idx_a, Ja in own:
                for idx_b, Jb in own:
                    H_f[f][np.ix_(idx_a, idx_b)] += Ja.T @ Jb
            ssr += float(r @ r)
            n_res += r.size
    return NormalEquations(H, g_f.sum(axis=0), ssr, n_res, residuals, g_f, H_f if per_frame else None)
