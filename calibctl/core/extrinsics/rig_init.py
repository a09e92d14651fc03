"""Starting point of the joint rig solve: per-view PnP, then a spanning tree of the camera graph.

Each camera's board pose in each frame comes from cv2.solvePnP with its intrinsics
(core.intrinsics.solve.fit_pose:
through the fisheye model for a fisheye member). A pair's relative
pose is the chordal mean over the frames both saw (rotation matrices averaged and projected back onto
SO(3), translations averaged). Cameras are reached from the root breadth-first along the pairs with
the most shared frames, so a weakly linked pair is used only when nothing better connects.

When the solve diverges, ``pair_spreads`` tells data that contradict themselves (cameras that moved
against each other, or photos not taken together) from a solver that failed: from the per-view poses
alone, whether any one frame's relative pose carries the board from one camera into the other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews, project_member
from calibctl.core.extrinsics.rig_tree import T_to_pose, pose_to_T
from calibctl.core.extrinsics.se3 import invert, rotation_angle_deg
from calibctl.core.intrinsics.solve import DEFAULT_MODEL, MAX_RMS_PX, fit_pose
from calibctl.errors import NumericalError


def view_poses(views: RigViews, members: Sequence[MemberIntrinsics]) -> dict[tuple[int, int], np.ndarray]:
    """(frame, camera) -> (4, 4) T_cam_board from solvePnP (fit_pose) with the member's intrinsics."""
    out = {}
    for f, row in enumerate(views.views):
        for c, view in enumerate(row):
            if view is None:
                continue
            m = members[c]
            pose = fit_pose(
                view.object_points(views.model_points_m),
                view.corners_px,
                m.camera_matrix,
                m.dist_coeffs,
                "fisheye" if m.lens == "fisheye" else DEFAULT_MODEL,
            )
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
            raise NumericalError(
                f"camera(s) {', '.join(missing)} share no board view with the rest of the rig",
                hint="capture frames in which the board is seen by both cameras of a pair",
            )
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
            raise NumericalError(
                f"frame {views.frames[f]}: no camera's board pose could be fitted", hint="drop that frame"
            )
        board_poses[f] = T_to_pose(mean_transform(estimates))
    return cam_poses, board_poses


@dataclass(frozen=True)
class PairSpread:
    """How far the per-frame relative poses of one pair (a < b, camera indices) are from one rigid pose.

    Attributes:
        n_frames: frames both cameras saw whose own board fits (PnP) leave at most ``MAX_RMS_PX``.
        baseline_mm: (min, max) of the per-frame baselines, mm.
        rotation_deg / rotation_frame: the largest per-frame rotation off their chordal mean, deg, and its
        frame.
        transfer_rms_px / transfer_frame: the best frame's relative pose put to every frame: camera a's board
            pose carried into camera b and projected through b's lens, per-corner RMS over all of them (px).
            It bounds what one rigid pose can do on these frames from above (with a's poses fixed).
    """

    a: int
    b: int
    n_frames: int
    baseline_mm: tuple[float, float]
    rotation_deg: float
    rotation_frame: str
    transfer_rms_px: float
    transfer_frame: str

    def words(self, cameras: Sequence[str]) -> str:
        return (
            f"{cameras[self.a]}-{cameras[self.b]}: per-frame baseline {self.baseline_mm[0]:.1f}-"
            f"{self.baseline_mm[1]:.1f} mm, rotation up to {self.rotation_deg:.2f} deg off the mean (frame "
            f"{self.rotation_frame}); the best frame's pose ({self.transfer_frame}) carries the board into "
            f"{cameras[self.b]} at {self.transfer_rms_px:.2f} px RMS over the {self.n_frames} frames"
        )


def _fit_rms_px(
    view: BoardView, model_points_m: np.ndarray, member: MemberIntrinsics, T_cam_board: np.ndarray
) -> float:
    """Per-corner RMS (px) of ``view``'s corners against the board at T_cam_board through the member's
    lens."""
    pose = T_to_pose(T_cam_board)
    proj, _ = project_member(view.object_points(model_points_m), pose[:3], pose[3:], member)
    return float(np.sqrt(np.mean(np.sum((view.corners_px - proj.reshape(-1, 2)) ** 2, axis=1))))


def pair_spreads(views: RigViews, members: Sequence[MemberIntrinsics]) -> list[PairSpread]:
    """Per pair with two or more usable frames (PairSpread): no solver involved, only per-view PnP.

    A frame is usable when each camera's own board pose explains its corners (PnP RMS <= MAX_RMS_PX):
    corners that do not fit their own camera say nothing about the rig. A rigid, synchronised pair's best
    frame carries the board into the other camera at about the corner noise (real pairs: opencv-left-right
    0.28 px, the sourishg fisheye pair 1.27 px; 2.95 px with a k1k2 lens on that fisheye); baka-stereo's
    webcams, neither rigid nor synchronised, 60.3 px.
    """
    poses = view_poses(views, members)
    good = {
        k
        for k, T in poses.items()
        if _fit_rms_px(views.views[k[0]][k[1]], views.model_points_m, members[k[1]], T)  # type: ignore[arg-type]
        <= MAX_RMS_PX
    }
    out = []
    n = len(views.cameras)
    for a in range(n):
        for b in range(a + 1, n):
            frames = [f for f in range(len(views.frames)) if (f, a) in good and (f, b) in good]
            if len(frames) < 2:
                continue
            rel = [poses[(f, b)] @ invert(poses[(f, a)]) for f in frames]
            mean = mean_transform(rel)
            base_mm = [float(np.linalg.norm(T[:3, 3]) * 1e3) for T in rel]
            rot_deg = [rotation_angle_deg(T[:3, :3] @ mean[:3, :3].T) for T in rel]
            transfer = [
                float(
                    np.sqrt(
                        np.mean(
                            [
                                _fit_rms_px(
                                    views.views[g][b],  # type: ignore[arg-type]
                                    views.model_points_m,
                                    members[b],
                                    T_b_a @ poses[(g, a)],
                                )
                                ** 2
                                for g in frames
                            ]
                        )
                    )
                )
                for T_b_a in rel
            ]
            worst, best = int(np.argmax(rot_deg)), int(np.argmin(transfer))
            out.append(
                PairSpread(
                    a,
                    b,
                    len(frames),
                    (min(base_mm), max(base_mm)),
                    rot_deg[worst],
                    views.frames[frames[worst]],
                    transfer[best],
                    views.frames[frames[best]],
                )
            )
    return out


def pair_spread(views: RigViews, members: Sequence[MemberIntrinsics]) -> str:
    """Words on how much the per-frame relative poses of each pair disagree (for a diverged solve)."""
    return "; ".join(s.words(views.cameras) for s in pair_spreads(views, members))
