"""Starting point of the joint rig solve: per-view PnP, then a spanning tree of the camera graph.

Each camera's board pose in each frame comes from cv2.solvePnP with its intrinsics (core.solve.fit_pose:
through the fisheye model for a fisheye member). A pair's relative
pose is the chordal mean over the frames both saw (rotation matrices averaged and projected back onto
SO(3), translations averaged). Cameras are reached from the root breadth-first along the pairs with
the most shared frames, so a weakly linked pair is used only when nothing better connects.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.extrinsics.rig_tree import T_to_pose, pose_to_T
from calibctl.core.extrinsics.se3 import invert, rotation_angle_deg
from calibctl.core.solve import DEFAULT_MODEL, fit_pose
from calibctl.errors import NumericalError


def view_poses(views: RigViews, members: Sequence[MemberIntrinsics]) -> dict[tuple[int, int], np.ndarray]:
    """(frame, camera) -> (4, 4) T_cam_board from solvePnP (fit_pose) with the member's intrinsics."""
    out = {}
    for f, row in enumerate(views.views):
        for c, view in enumerate(row):
            if view is None:
                continue
            m = members[c]
            pose = fit_pose(view.object_points(views.model_points_m), view.corners_px, m.camera_matrix,
                            m.dist_coeffs, "fisheye" if m.lens == "fisheye" else DEFAULT_MODEL)
            if pose is not None:
                out[(f, c)] = pose_to_T(np.concatenate([np.ravel(pose[0]), np.ravel(pose[1])]))
    return out


def mean_transform(Ts: Sequence[np.ndarray]) -> np.ndarray:
    """Chordal mean of rigid transforms: SVD projection of the mean rotation, mean translation."""
    R_mean = np.mean([T[:3, :3] for T in Ts], axis=0)
    U, _, Vt = np.linalg.svd(R_mean)
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    out = np.eye(4)
    out[:3, :3] = R
    out[:3, 3] = np.mean([T[:3, 3] for T in Ts], axis=0)
    return out


def initial_poses(views: RigViews, members: Sequence[MemberIntrinsics]) -> tuple[np.ndarray, np.ndarray]:
    """(C, 6) T_cam_root pose vectors (row 0 zero) and (F, 6) T_root_board pose vectors.

    Raises:
        NumericalError: a camera shares no frame with the cameras already placed (graph not connected).
    """
    poses = view_poses(views, members)
    n_cams, n_frames = len(views.cameras), len(views.frames)
    T_cam_root: dict[int, np.ndarray] = {0: np.eye(4)}
    while len(T_cam_root) < n_cams:
        best: tuple[int, int, list[int]] | None = None
        for a in T_cam_root:
            for b in range(n_cams):
                if b in T_cam_root:
                    continue
                shared = [f for f in range(n_frames) if (f, a) in poses and (f, b) in poses]
                if shared and (best is None or len(shared) > len(best[2])):
                    best = (a, b, shared)
        if best is None:
            missing = [views.cameras[c] for c in range(n_cams) if c not in T_cam_root]
            raise NumericalError(f"camera(s) {', '.join(missing)} share no board view with the rest of the rig",
                                 hint="capture frames in which the board is seen by both cameras of a pair")
        a, b, shared = best
        T_b_a = mean_transform([poses[(f, b)] @ invert(poses[(f, a)]) for f in shared])
        T_cam_root[b] = T_b_a @ T_cam_root[a]
    cam_poses = np.zeros((n_cams, 6))
    for c in range(1, n_cams):
        cam_poses[c] = T_to_pose(T_cam_root[c])
    board_poses = np.zeros((n_frames, 6))
    for f in range(n_frames):
        estimates = [invert(T_cam_root[c]) @ poses[(f, c)] for c in range(n_cams) if (f, c) in poses]
        if not estimates:
            raise NumericalError(f"frame {views.frames[f]}: no camera's board pose could be fitted",
                                 hint="drop that frame")
        board_poses[f] = T_to_pose(mean_transform(estimates))
    return cam_poses, board_poses


def pair_spread(views: RigViews, members: Sequence[MemberIntrinsics]) -> str:
    """Words on how much the per-frame relative poses of each pair disagree (for a diverged solve)."""
    poses = view_poses(views, members)
    parts = []
    n = len(views.cameras)
    for a in range(n):
        for b in range(a + 1, n):
            rel = [poses[(f, b)] @ invert(poses[(f, a)]) for f in range(len(views.frames))
                   if (f, a) in poses and (f, b) in poses]
            if len(rel) < 2:
                continue
            mean = mean_transform(rel)
            base_mm = [float(np.linalg.norm(T[:3, 3]) * 1e3) for T in rel]
            rot_deg = [rotation_angle_deg(T[:3, :3] @ mean[:3, :3].T) for T in rel]
            worst = int(np.argmax(rot_deg))
            frame = [views.frames[f] for f in range(len(views.frames)) if (f, a) in poses and (f, b) in poses][worst]
            parts.append(f"{views.cameras[a]}-{views.cameras[b]}: per-frame baseline {min(base_mm):.1f}-"
                         f"{max(base_mm):.1f} mm, rotation up to {max(rot_deg):.2f} deg off the mean (frame {frame})")
    return "; ".join(parts)
