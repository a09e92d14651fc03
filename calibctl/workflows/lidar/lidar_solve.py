"""``calibctl lidar solve``: pair, segment, pose, gate, solve, judge (docs/lidar.md).

Every scan gets an outcome: ``accepted``, ``no_plane``, ``too_few_rings``, ``dimension_mismatch``,
``no_board_in_image`` or ``not_paired``. The gates before the solve refuse a set that cannot determine
T (exit 1, no transform); the gates after it judge the transform. The result is a JSON-ready dict.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibctl import bounded, files
from calibctl.config import Settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import detect_board
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.extrinsics.rig_frames import frame_key
from calibctl.core.gate import GateResult
from calibctl.core.lidar import gates, validation
from calibctl.core.lidar import solve as lsolve
from calibctl.core.lidar.pcd import PointCloud
from calibctl.core.lidar.segment import (
    DEFAULT_MAX_DIMENSION_ERROR_M,
    DEFAULT_MIN_RINGS,
    StationBox,
    segment_board,
)
from calibctl.core.lidar.target import BackingBoard, CameraBoard, pose_covariance
from calibctl.errors import InputError, UsageError
from calibctl.workflows.lidar.camera import Lens, load_lens
from calibctl.workflows.lidar.scans import SCAN_SUFFIXES, pair, read_scan


@dataclass(frozen=True)
class LidarRequest:
    """What the command line asked for (units as named)."""

    images: Path
    scans: Path
    board: BackingBoard
    box: StationBox
    camera_info: Path | None = None
    serial: str | None = None
    scan_pattern: str = "*"
    scan_scale_to_m: float = 1.0
    range_offset_m: float = 0.0
    estimate_range_offset: bool = False
    min_rings: int = DEFAULT_MIN_RINGS
    max_dimension_error_m: float = DEFAULT_MAX_DIMENSION_ERROR_M
    min_poses: int = gates.MIN_POSES
    folds: int = 5
    overlay_dir: Path | None = None
    force: bool = False


@dataclass
class LidarOutcome:
    """The result document and the verdict."""

    result: dict[str, Any]
    accepted: bool
    scans: list[dict[str, Any]] = field(default_factory=list)


def parse_box(text: str) -> StationBox:
    """``xmin,ymin,zmin,xmax,ymax,zmax`` metres (LiDAR frame) -> StationBox; UsageError when malformed."""
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 6 or not np.isfinite(v).all() or any(lo >= hi for lo, hi in zip(v[:3], v[3:], strict=True)):
        raise UsageError(
            f"--box {text!r} is not xmin,ymin,zmin,xmax,ymax,zmax with each min < max (metres)",
            "e.g. --box 1.0,-2.2,-0.8,3.6,1.6,0.6: the region where the board is held, LiDAR frame",
        )
    return StationBox((v[0], v[1], v[2]), (v[3], v[4], v[5]))


def board_from_store(settings: Settings, ref: str) -> BackingBoard:
    """The registered board ``NAME[@REV]`` as the solve's target; UsageError (exit 2) when it was
    registered without its backing board."""
    from calibctl.workflows.board.boards import board_ref
    from calibctl.workflows.store_admin.records import open_store

    name, revision = board_ref(ref)
    with open_store(settings) as store:
        board = store.get_board(name, revision)  # NotFoundError (exit 2) for an unknown board
    if board.kind != "chessboard":
        raise UsageError(f"board {board.ref} is a {board.kind}; the camera-LiDAR solve takes a chessboard")
    if board.backing is None:
        raise UsageError(
            f"board {board.ref} was registered without its backing board dimensions",
            f"register its next revision with them: calibctl board add {board.name} --cols {board.cols} "
            f"--rows {board.rows} --square-mm ... --backing-mm W,H [--pattern-offset-mm X,Y]",
        )
    b = board.backing
    return BackingBoard(
        board.cols,
        board.rows,
        board.square_size_m,
        (b.width_m, b.height_m),
        (b.pattern_offset_m[0], b.pattern_offset_m[1]),
    )


def _camera_board(path: Path, lens: Lens, board: BackingBoard) -> tuple[CameraBoard | None, str]:
    bounded.check_size(path, "read image")
    with files.file_errors("read image", path):
        data = path.read_bytes()
    gray = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE) if data else None
    if gray is None:
        raise InputError(
            f"{path} is not a readable image", "remove it or give the folder of the camera's images"
        )
    if (gray.shape[1], gray.shape[0]) != lens.image_size:
        raise InputError(
            f"{path.name} is {gray.shape[1]}x{gray.shape[0]} but the lens ({lens.source}) is "
            f"{lens.image_size[0]}x{lens.image_size[1]}",
            "use the images the calibration is for",
        )
    spec = BoardSpec.chessboard(board.cols, board.rows, board.square_m)
    detection, why = detect_board(gray, spec)
    if detection is None:
        return None, why or "no board"
    obj = spec.object_points()[detection.corner_ids]
    T, _ = estimate_board_pose(obj, detection.corners_px, lens.camera_matrix, lens.dist_coeffs, lens.model)
    if T is None:
        return None, "no board pose fits the corners"
    cov, rms = pose_covariance(T, obj, detection.corners_px, lens.camera_matrix, lens.dist_coeffs, lens.model)
    return CameraBoard(T, cov, rms), ""


def _shifted(cloud: PointCloud, range_offset_m: float) -> PointCloud:
    if range_offset_m == 0.0 or not len(cloud.points_m):
        return cloud
    r = np.linalg.norm(cloud.points_m, axis=1, keepdims=True)
    return PointCloud(
        cloud.points_m * (r + range_offset_m) / np.maximum(r, 1e-9),
        cloud.intensity,
        cloud.ring,
        cloud.time_s,
        cloud.dropped_nonfinite,
    )


def _gate_json(g: GateResult) -> dict[str, Any]:
    return {
        "gate": g.gate,
        "passed": g.passed,
        "value": round(g.value, 4),
        "threshold": round(g.threshold, 4),
        "message": g.message,
        "reason": g.reason,
        "hint": g.hint,
        "detail": g.detail,
    }


def collect_poses(req: LidarRequest, lens: Lens) -> tuple[list[lsolve.Pose], list[dict[str, Any]]]:
    """Each paired scan segmented and each image posed; (accepted poses, one outcome row per file)."""
    pairing = pair(req.images, req.scans, req.scan_pattern)
    rows: list[dict[str, Any]] = [
        {
            "frame": frame_key(p),
            "image": None if p.suffix.lower() in SCAN_SUFFIXES else p.name,
            "scan": p.name if p.suffix.lower() in SCAN_SUFFIXES else None,
            "outcome": "not_paired",
            "message": why,
        }
        for p, why in pairing.unpaired
    ]
    poses = []
    for key, image, scan in pairing.pairs:
        cloud = _shifted(read_scan(scan, req.scan_scale_to_m), req.range_offset_m)
        found = segment_board(
            cloud,
            req.box,
            req.board.backing_m,
            min_rings=req.min_rings,
            max_dimension_error_m=req.max_dimension_error_m,
        )
        camera, why = _camera_board(image, lens, req.board)
        row: dict[str, Any] = {
            "frame": key,
            "image": image.name,
            "scan": scan.name,
            "outcome": found.outcome,
            "message": found.message,
            "points_in_box": found.points_in_box,
            "rings": found.rings,
            "dropped_nonfinite": cloud.dropped_nonfinite,
            "plane_rms_mm": round(found.plane_rms_m * 1e3, 2),
            "range_m": round(found.range_m, 3),
            "width_mm": round(found.width_m * 1e3, 1),
            "height_mm": round(found.height_m * 1e3, 1),
            "dimension_error_mm": [round(e * 1e3, 1) for e in found.dimension_error_m],
            "image_rms_px": None if camera is None else round(camera.rms_px, 3),
        }
        if found.accepted and camera is None:
            row["outcome"], row["message"] = "no_board_in_image", why
        if row["outcome"] == "accepted" and camera is not None:
            poses.append(lsolve.Pose(f"{key}", camera, found))
        rows.append(row)
    rows.sort(key=lambda r: (r["frame"] is None, r["frame"] or 0, r["scan"] or "", r["image"] or ""))
    return poses, rows


def projected_edge_px(
    T_lidar_cam: np.ndarray, poses: Sequence[lsolve.Pose], board: BackingBoard, lens: Lens
) -> np.ndarray:
    """Pixel distance, in the image, between each LiDAR ring end point (through T_cam_lidar and the lens)
    and the nearest point of the backing board's outline as the camera sees it."""
    from calibctl.core.intrinsics.solve import project_points

    dists = []
    half = np.array(board.backing_m) / 2
    centre = board.centre_in_pattern()[:2]
    for p in poses:
        T_board_lidar = se3.invert(T_lidar_cam @ p.camera.T_cam_board)
        e = p.lidar.edge_points_m @ T_board_lidar[:3, :3].T + T_board_lidar[:3, 3]
        rel = e[:, :2] - centre
        on = rel.copy()
        nearest = np.argmin(np.abs(np.abs(rel) - half), axis=1)
        rows = np.arange(len(rel))
        on[rows, nearest] = np.sign(rel[rows, nearest]) * half[nearest]
        outline = np.column_stack([on + centre, np.zeros(len(on))])
        seen = np.column_stack([e[:, :2], np.zeros(len(e))])  # the end point, on the board's plane
        rvec = se3.rotvec_from_rotation(p.camera.T_cam_board[:3, :3])
        tvec = p.camera.T_cam_board[:3, 3].copy()
        a = project_points(outline, rvec, tvec, lens.camera_matrix, lens.dist_coeffs, lens.model)
        b = project_points(seen, rvec, tvec, lens.camera_matrix, lens.dist_coeffs, lens.model)
        dists.append(np.linalg.norm(a - b, axis=1))
    return np.concatenate(dists) if dists else np.zeros(0)


def _transform_json(sol: lsolve.LidarSolution) -> dict[str, Any]:
    T = sol.T_lidar_cam
    roll, pitch, yaw = validation.rpy_from_rotation(T[:3, :3])
    return {
        "name": "T_lidar_cam",
        "convention": "p_lidar = R p_cam + t (camera frame into the LiDAR frame)",
        "matrix": [[round(float(v), 9) for v in row] for row in T],
        "translation_m": [round(float(v), 6) for v in T[:3, 3]],
        "rpy_rad": [round(v, 6) for v in (roll, pitch, yaw)],
        "rpy_order": "R = Rz(yaw) Ry(pitch) Rx(roll) (acfr/cam_lidar_calibration, tf setRPY)",
        "quaternion_wxyz": [round(float(v), 9) for v in se3.quaternion_from_rotation(T[:3, :3])],
        "sigma_translation_mm": [round(float(v) * 1e3, 3) for v in sol.sigma_translation_m],
        "sigma_rotation_deg": [round(float(v), 4) for v in sol.sigma_rotation_deg],
        "covariance": [[float(v) for v in row] for row in sol.covariance],
        "covariance_order": "rotation about LiDAR x, y, z (rad), translation x, y, z (m); left perturbation",
        "T_cam_lidar": [[round(float(v), 9) for v in row] for row in se3.invert(T)],
    }


def run_lidar_solve(settings: Settings, req: LidarRequest) -> LidarOutcome:
    """The whole command (module docstring)."""
    problem = req.board.check_pattern_fits()
    if problem:
        raise UsageError(
            problem, "check --backing-mm (width,height of the backing board) and --pattern-offset-mm"
        )
    lens = load_lens(settings, req.camera_info, req.serial)
    poses, rows = collect_poses(req, lens)
    n_scans = sum(1 for r in rows if r["scan"] is not None)
    pre = [gates.pose_count_gate(len(poses), n_scans, req.min_poses)]
    if len(poses) >= 1:
        pre += [
            gates.observability_gate(np.array([p.lidar.normal for p in poses])),
            gates.range_spread_gate([p.lidar.range_m for p in poses]),
        ]
    result: dict[str, Any] = {
        "images": str(req.images),
        "scans": str(req.scans),
        "lens": lens.source,
        "lens_model": lens.model,
        "range_offset_applied_mm": req.range_offset_m * 1e3,
        "outcomes": rows,
        "transform": None,
    }
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    result["outcome_counts"] = counts
    if not all(g.passed for g in pre):
        result |= {"status": "rejected", "gates": [_gate_json(g) for g in pre]}
        return LidarOutcome(result, False, rows)
    sol = lsolve.solve(poses, req.board, req.estimate_range_offset)
    held_plane, held_edge, held_px = validation.held_out(
        poses, req.board, req.folds, lambda T, test: projected_edge_px(T, test, req.board, lens)
    )
    in_px = projected_edge_px(sol.T_lidar_cam, poses, req.board, lens)
    dims = np.array([p.lidar.dimension_error_m for p in poses]) * 1e3
    dim_offset, dim_offset_sigma = validation.range_offset_from_dimensions(
        [p.lidar for p in poses], req.board.backing_m
    )
    post = [
        gates.plane_rms_gate(sol.plane_rms_m * 1e3),
        gates.dimension_gate(dims),
        gates.held_out_gate(held_plane * 1e3, sol.plane_rms_m * 1e3),
    ]
    all_gates = pre + post
    accepted = all(g.passed for g in all_gates)
    result |= {
        "status": "accepted" if accepted else "rejected",
        "gates": [_gate_json(g) for g in all_gates],
        "transform": _transform_json(sol),
        "metrics": {
            "poses": len(poses),
            "plane_rms_mm": round(sol.plane_rms_m * 1e3, 2),
            "edge_rms_mm": round(sol.edge_rms_m * 1e3, 2),
            "projected_edge_rms_px": round(float(np.sqrt(np.mean(in_px**2))), 2),
            "held_out_projected_edge_rms_px": round(held_px, 2),
            "held_out_plane_rms_mm": round(held_plane * 1e3, 2),
            "held_out_edge_rms_mm": round(held_edge * 1e3, 2),
            "folds": req.folds,
            "dimension_error_mean_mm": [round(float(v), 1) for v in dims.mean(axis=0)],
            "range_offset_from_dimensions_mm": round(dim_offset * 1e3, 1),
            "range_offset_from_dimensions_sigma_mm": round(dim_offset_sigma * 1e3, 1),
            "range_offset_estimated_mm": round(sol.range_offset_m * 1e3, 2)
            if req.estimate_range_offset
            else None,
            "range_offset_estimated_sigma_mm": (
                round(sol.range_offset_sigma_m * 1e3, 2) if sol.range_offset_sigma_m is not None else None
            ),
            "noise_white_mm": round(sol.noise.white_m * 1e3, 2),
            "noise_laser_mm": round(sol.noise.run_bias_m * 1e3, 2),
            "pose_offset_sigma_mm": round(sol.pose_offset_sigma_m * 1e3, 2),
            "pose_tilt_sigma_deg": round(float(np.degrees(sol.pose_tilt_sigma_rad)), 3),
        },
    }
    if req.overlay_dir is not None:
        accepted_frames = {int(p.label) for p in poses}
        pairs = [
            (img, scan)
            for key, img, scan in pair(req.images, req.scans, req.scan_pattern).pairs
            if key in accepted_frames
        ]
        from calibctl.workflows.lidar.lidar_overlay import write_overlays

        result["overlays"] = write_overlays(
            req.overlay_dir, pairs, sol.T_lidar_cam, lens, req.scan_scale_to_m, req.force
        )
    return LidarOutcome(_finite(result), accepted, rows)


def tf_static_yaml(result: dict[str, Any], lidar_frame: str, camera_frame: str) -> str:
    """An accepted result's T_lidar_cam as a tf2_msgs/TFMessage YAML (what `ros2 topic echo /tf_static`
    prints): parent ``lidar_frame``, child ``camera_frame`` (tf's transform is the child's pose in the parent)."""
    from calibctl.workflows.exports.rig_exports import tf_message

    t = result.get("transform")
    if result.get("status") != "accepted" or t is None:
        raise UsageError("a rejected camera-LiDAR result has no transform to export")
    w, x, y, z = t["quaternion_wxyz"]
    header = f"# calibctl lidar solve T_{lidar_frame}_{camera_frame} (images {result['images']}, scans {result['scans']})\n"
    return header + tf_message([(lidar_frame, camera_frame, t["translation_m"], (x, y, z, w))])


def _finite(doc: Any) -> Any:
    """``doc`` with every NaN/inf number as None (JSON has no NaN; a metric that could not be computed)."""
    if isinstance(doc, dict):
        return {k: _finite(v) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_finite(v) for v in doc]
    if isinstance(doc, float) and not np.isfinite(doc):
        return None
    return doc
