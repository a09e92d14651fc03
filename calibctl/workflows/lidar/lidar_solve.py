"""``calibctl lidar solve``: pair, segment, pose, gate, solve, judge (docs/lidar.md).

Every scan gets an outcome: ``accepted``, ``no_plane``, ``too_few_rings``, ``dimension_mismatch``,
``no_board_in_image`` or ``not_paired``. The gates before the solve refuse a set that cannot determine
T (exit 1, no transform); the gates after it judge the transform. The result is typed (``LidarOutcome``,
full float precision: the rig's evidence is built from it); ``result_json`` is its one JSON shape, rounded
for people, that ``--json`` prints and ``-o`` writes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

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

if TYPE_CHECKING:
    from calibctl.artifacts.rig import RigCalibration
from calibctl.workflows.lidar.camera import Lens, load_lens
from calibctl.workflows.lidar.scans import SCAN_SUFFIXES, pair, read_scan

LENS_RMS_LIMIT_PX = 0.6  # median corner RMS of the board poses: acfr 0.17, pinhole images read as fisheye 1.0
SCALE_LIMIT = (
    0.025  # camera / LiDAR pose-to-pose distance - 1: acfr 0.005, rendered 0.002; 100 mm for 95: 0.054
)


@dataclass(frozen=True)
class LidarRequest:
    """What the command line asked for (units as named). ``board``: the target's dimensions, or a registered
    board NAME[@REV] that ``run_lidar_solve`` reads from the store."""

    images: Path
    scans: Path
    board: BackingBoard | str
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

    @property
    def backing(self) -> BackingBoard:
        """The target's dimensions (after ``run_lidar_solve`` read a registered board)."""
        if isinstance(self.board, str):
            raise UsageError(f"board {self.board} was not read from the store before the solve")
        return self.board


@dataclass(frozen=True)
class ScanFigures:
    """What segmentation and the board pose measured on one paired scan."""

    points_in_box: int
    rings: int
    dropped_nonfinite: int
    plane_rms_mm: float
    range_m: float
    width_mm: float
    height_mm: float
    dimension_error_mm: tuple[float, ...]
    image_rms_px: float | None


@dataclass(frozen=True)
class ScanRow:
    """One scan's (or unpaired file's) outcome; ``figures`` for a paired one."""

    frame: int | None
    image: str | None
    scan: str | None
    outcome: str
    message: str
    figures: ScanFigures | None = None


@dataclass(frozen=True)
class LidarFit:
    """T_lidar_cam (p_lidar = R p_cam + t) with its 6x6 covariance (rotation about LiDAR x, y, z rad,
    translation x, y, z m; left perturbation) and one-sigmas."""

    T_lidar_cam: np.ndarray
    covariance: np.ndarray
    sigma_translation_mm: tuple[float, float, float]
    sigma_rotation_deg: tuple[float, float, float]

    @property
    def rpy_rad(self) -> tuple[float, float, float]:
        roll, pitch, yaw = validation.rpy_from_rotation(self.T_lidar_cam[:3, :3])
        return (float(roll), float(pitch), float(yaw))

    @property
    def quaternion_wxyz(self) -> tuple[float, float, float, float]:
        w, x, y, z = (float(v) for v in se3.quaternion_from_rotation(self.T_lidar_cam[:3, :3]))
        return (w, x, y, z)


@dataclass(frozen=True)
class LidarFitMetrics:
    """Fit and held-out figures of a solve (NaN where not computable)."""

    poses: int
    plane_rms_mm: float
    edge_rms_mm: float
    projected_edge_rms_px: float
    held_out_projected_edge_rms_px: float
    held_out_plane_rms_mm: float
    held_out_edge_rms_mm: float
    folds: int
    dimension_error_mean_mm: tuple[float, float]
    range_offset_from_dimensions_mm: float
    range_offset_from_dimensions_sigma_mm: float
    range_offset_estimated_mm: float | None
    range_offset_estimated_sigma_mm: float | None
    noise_white_mm: float
    noise_laser_mm: float
    pose_offset_sigma_mm: float
    pose_tilt_sigma_deg: float


@dataclass
class LidarOutcome:
    """The typed result and the verdict; ``fit`` and ``metrics`` are None when a gate refused the set before
    the solve. ``written`` and ``stored`` are filled by ``lidar_run.run_lidar``."""

    images: str
    scans: str
    lens: str
    lens_model: str
    range_offset_applied_mm: float
    rows: list[ScanRow]
    gates: list[GateResult]
    fit: LidarFit | None = None
    metrics: LidarFitMetrics | None = None
    overlays: list[str] | None = None
    notes: list[str] = field(default_factory=list)
    written: list[str] = field(default_factory=list)
    stored: RigCalibration | None = None

    @property
    def accepted(self) -> bool:
        return self.fit is not None and all(g.passed for g in self.gates)

    @property
    def status(self) -> str:
        return "accepted" if self.accepted else "rejected"


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


def _gray(path: Path) -> np.ndarray | None:
    """The image at ``path`` in gray, bounded; None when it does not decode."""
    bounded.check_size(path, "read image")
    with files.file_errors("read image", path):
        data = path.read_bytes()
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE) if data else None


def _camera_board(path: Path, lens: Lens, board: BackingBoard) -> tuple[CameraBoard | None, str]:
    gray = _gray(path)
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


def collect_poses(req: LidarRequest, lens: Lens) -> tuple[list[lsolve.Pose], list[ScanRow]]:
    """Each paired scan segmented and each image posed; (accepted poses, one outcome row per file)."""
    pairing = pair(req.images, req.scans, req.scan_pattern)
    board = req.backing
    rows = [
        ScanRow(
            frame_key(p),
            None if p.suffix.lower() in SCAN_SUFFIXES else p.name,
            p.name if p.suffix.lower() in SCAN_SUFFIXES else None,
            "not_paired",
            why,
        )
        for p, why in pairing.unpaired
    ]
    poses = []
    for key, image, scan in pairing.pairs:
        cloud = _shifted(read_scan(scan, req.scan_scale_to_m), req.range_offset_m)
        found = segment_board(
            cloud,
            req.box,
            board.backing_m,
            min_rings=req.min_rings,
            max_dimension_error_m=req.max_dimension_error_m,
        )
        camera, why = _camera_board(image, lens, board)
        figures = ScanFigures(
            found.points_in_box,
            found.rings,
            cloud.dropped_nonfinite,
            found.plane_rms_m * 1e3,
            found.range_m,
            found.width_m * 1e3,
            found.height_m * 1e3,
            tuple(e * 1e3 for e in found.dimension_error_m),
            None if camera is None else camera.rms_px,
        )
        outcome, message = found.outcome, found.message
        if found.accepted and camera is None:
            outcome, message = "no_board_in_image", why
        if outcome == "accepted" and camera is not None:
            poses.append(lsolve.Pose(f"{key}", camera, found))
        rows.append(ScanRow(key, image.name, scan.name, outcome, message, figures))
    rows.sort(key=lambda r: (r.frame is None, r.frame or 0, r.scan or "", r.image or ""))
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


def _transform_json(fit: LidarFit) -> dict[str, Any]:
    T = fit.T_lidar_cam
    return {
        "name": "T_lidar_cam",
        "convention": "p_lidar = R p_cam + t (camera frame into the LiDAR frame)",
        "matrix": [[round(float(v), 9) for v in row] for row in T],
        "translation_m": [round(float(v), 6) for v in T[:3, 3]],
        "rpy_rad": [round(v, 6) for v in fit.rpy_rad],
        "rpy_order": "R = Rz(yaw) Ry(pitch) Rx(roll) (acfr/cam_lidar_calibration, tf setRPY)",
        "quaternion_wxyz": [round(v, 9) for v in fit.quaternion_wxyz],
        "sigma_translation_mm": [round(v, 3) for v in fit.sigma_translation_mm],
        "sigma_rotation_deg": [round(v, 4) for v in fit.sigma_rotation_deg],
        "covariance": [[float(v) for v in row] for row in fit.covariance],
        "covariance_order": "rotation about LiDAR x, y, z (rad), translation x, y, z (m); left perturbation",
        "T_cam_lidar": [[round(float(v), 9) for v in row] for row in se3.invert(T)],
    }


def _row_json(r: ScanRow) -> dict[str, Any]:
    row: dict[str, Any] = {
        "frame": r.frame,
        "image": r.image,
        "scan": r.scan,
        "outcome": r.outcome,
        "message": r.message,
    }
    f = r.figures
    if f is not None:
        row |= {
            "points_in_box": f.points_in_box,
            "rings": f.rings,
            "dropped_nonfinite": f.dropped_nonfinite,
            "plane_rms_mm": round(f.plane_rms_mm, 2),
            "range_m": round(f.range_m, 3),
            "width_mm": round(f.width_mm, 1),
            "height_mm": round(f.height_mm, 1),
            "dimension_error_mm": [round(e, 1) for e in f.dimension_error_mm],
            "image_rms_px": None if f.image_rms_px is None else round(f.image_rms_px, 3),
        }
    return row


def _metrics_json(m: LidarFitMetrics) -> dict[str, Any]:
    def r(v: float | None, digits: int) -> float | None:
        return None if v is None else round(v, digits)

    return {
        "poses": m.poses,
        "plane_rms_mm": r(m.plane_rms_mm, 2),
        "edge_rms_mm": r(m.edge_rms_mm, 2),
        "projected_edge_rms_px": r(m.projected_edge_rms_px, 2),
        "held_out_projected_edge_rms_px": r(m.held_out_projected_edge_rms_px, 2),
        "held_out_plane_rms_mm": r(m.held_out_plane_rms_mm, 2),
        "held_out_edge_rms_mm": r(m.held_out_edge_rms_mm, 2),
        "folds": m.folds,
        "dimension_error_mean_mm": [r(v, 1) for v in m.dimension_error_mean_mm],
        "range_offset_from_dimensions_mm": r(m.range_offset_from_dimensions_mm, 1),
        "range_offset_from_dimensions_sigma_mm": r(m.range_offset_from_dimensions_sigma_mm, 1),
        "range_offset_estimated_mm": r(m.range_offset_estimated_mm, 2),
        "range_offset_estimated_sigma_mm": r(m.range_offset_estimated_sigma_mm, 2),
        "noise_white_mm": r(m.noise_white_mm, 2),
        "noise_laser_mm": r(m.noise_laser_mm, 2),
        "pose_offset_sigma_mm": r(m.pose_offset_sigma_mm, 2),
        "pose_tilt_sigma_deg": r(m.pose_tilt_sigma_deg, 3),
    }


def result_json(outcome: LidarOutcome) -> dict[str, Any]:
    """The result as the JSON people and scripts read (``--json``, ``-o``): rounded for reading, NaN as
    null; the rig's evidence is built from ``outcome`` itself, at full precision."""
    counts: dict[str, int] = {}
    for row in outcome.rows:
        counts[row.outcome] = counts.get(row.outcome, 0) + 1
    doc: dict[str, Any] = {
        "images": outcome.images,
        "scans": outcome.scans,
        "lens": outcome.lens,
        "lens_model": outcome.lens_model,
        "range_offset_applied_mm": outcome.range_offset_applied_mm,
        "outcomes": [_row_json(r) for r in outcome.rows],
        "transform": None if outcome.fit is None else _transform_json(outcome.fit),
        "outcome_counts": counts,
        "status": outcome.status,
        "gates": [_gate_json(g) for g in outcome.gates],
    }
    if outcome.metrics is not None:
        doc["metrics"] = _metrics_json(outcome.metrics)
    if outcome.overlays is not None:
        doc["overlays"] = outcome.overlays
    doc["notes"] = list(outcome.notes)
    return _finite(doc)


def run_lidar_solve(settings: Settings, req: LidarRequest) -> LidarOutcome:
    """The whole solve (module docstring); a registered ``req.board`` is read from the store first."""
    named = req.board
    if isinstance(req.board, str):
        req = replace(req, board=board_from_store(settings, req.board))
    board = req.backing
    problem = board.check_pattern_fits()
    if problem:
        raise UsageError(
            problem, "check --backing-mm (width,height of the backing board) and --pattern-offset-mm"
        )
    lens = load_lens(settings, req.camera_info, req.serial)
    poses, rows = collect_poses(req, lens)
    if not poses:
        _refuse_an_unseen_pattern(req, rows, named)
    n_scans = sum(1 for r in rows if r.scan is not None)
    pre = [gates.pose_count_gate(len(poses), n_scans, req.min_poses)]
    if len(poses) >= 1:
        pre += [
            gates.observability_gate(np.array([p.lidar.normal for p in poses])),
            gates.range_spread_gate([p.lidar.range_m for p in poses]),
        ]
    outcome = LidarOutcome(
        str(req.images), str(req.scans), lens.source, lens.model, req.range_offset_m * 1e3, rows, pre
    )
    cause = _likely_cause(poses, board, lens, named)
    if not all(g.passed for g in pre):
        outcome.gates = _blaming(pre, cause)
        return outcome
    sol = lsolve.solve(poses, board, req.estimate_range_offset)
    folds = min(req.folds, len(poses))
    if folds < req.folds:
        outcome.notes.append(
            f"--folds {req.folds} is more than the {len(poses)} accepted poses: the held-out check ran "
            f"{folds}-fold (leave-one-out); give --folds {len(poses)} or fewer"
        )
    held_plane, held_edge, held_px = validation.held_out(
        poses, board, folds, lambda T, test: projected_edge_px(T, test, board, lens)
    )
    in_px = projected_edge_px(sol.T_lidar_cam, poses, board, lens)
    dims = np.array([p.lidar.dimension_error_m for p in poses]) * 1e3
    dim_offset, dim_offset_sigma = validation.range_offset_from_dimensions(
        [p.lidar for p in poses], board.backing_m
    )
    outcome.gates = _blaming(
        pre
        + [
            gates.plane_rms_gate(sol.plane_rms_m * 1e3),
            gates.dimension_gate(dims),
            gates.held_out_gate(held_plane * 1e3, sol.plane_rms_m * 1e3),
        ],
        cause,
    )
    if cause is not None and all(g.passed for g in outcome.gates):
        outcome.notes.append(cause)
    st, sr = sol.sigma_translation_m * 1e3, sol.sigma_rotation_deg
    outcome.fit = LidarFit(
        sol.T_lidar_cam,
        sol.covariance,
        (float(st[0]), float(st[1]), float(st[2])),
        (float(sr[0]), float(sr[1]), float(sr[2])),
    )
    mean_dims = dims.mean(axis=0)
    outcome.metrics = LidarFitMetrics(
        poses=len(poses),
        plane_rms_mm=sol.plane_rms_m * 1e3,
        edge_rms_mm=sol.edge_rms_m * 1e3,
        projected_edge_rms_px=float(np.sqrt(np.mean(in_px**2))),
        held_out_projected_edge_rms_px=held_px,
        held_out_plane_rms_mm=held_plane * 1e3,
        held_out_edge_rms_mm=held_edge * 1e3,
        folds=folds,
        dimension_error_mean_mm=(float(mean_dims[0]), float(mean_dims[1])),
        range_offset_from_dimensions_mm=dim_offset * 1e3,
        range_offset_from_dimensions_sigma_mm=dim_offset_sigma * 1e3,
        range_offset_estimated_mm=sol.range_offset_m * 1e3 if req.estimate_range_offset else None,
        range_offset_estimated_sigma_mm=(
            sol.range_offset_sigma_m * 1e3 if sol.range_offset_sigma_m is not None else None
        ),
        noise_white_mm=sol.noise.white_m * 1e3,
        noise_laser_mm=sol.noise.run_bias_m * 1e3,
        pose_offset_sigma_mm=sol.pose_offset_sigma_m * 1e3,
        pose_tilt_sigma_deg=float(np.degrees(sol.pose_tilt_sigma_rad)),
    )
    if req.overlay_dir is not None:
        accepted_frames = {int(p.label) for p in poses}
        pairs = [
            (img, scan)
            for key, img, scan in pair(req.images, req.scans, req.scan_pattern).pairs
            if key in accepted_frames
        ]
        from calibctl.workflows.lidar.lidar_overlay import write_overlays

        outcome.overlays = write_overlays(
            req.overlay_dir, pairs, sol.T_lidar_cam, lens, req.scan_scale_to_m, req.force
        )
    return outcome


def _likely_cause(
    poses: Sequence[lsolve.Pose], board: BackingBoard, lens: Lens, named: BackingBoard | str
) -> str | None:
    """What is wrong with the inputs rather than the poses, when the accepted poses show it: a lens that
    does not fit the images (median corner RMS over ``LENS_RMS_LIMIT_PX``), or a square size the camera and
    the LiDAR disagree on (``validation.camera_to_lidar_scale`` off 1 by more than ``SCALE_LIMIT``)."""
    if len(poses) < 2:
        return None
    rms = float(np.median([p.camera.rms_px for p in poses]))
    if rms > LENS_RMS_LIMIT_PX:
        return (
            f"the board's corners fit the lens ({lens.model}, {lens.source}) with a median RMS of "
            f"{rms:.2f} px over {len(poses)} images (a lens that matches fits under {LENS_RMS_LIMIT_PX} px): "
            "these images do not match that lens or its model (fisheye images declared plumb_bob, or the "
            "reverse?); give the calibration of the camera that took them"
        )
    scale = validation.camera_to_lidar_scale(poses, board)
    if not abs(scale - 1) > SCALE_LIMIT:
        return None
    square_mm = board.square_m * 1e3
    check = (
        f"the board's registered square size (`calibctl board show {named.partition('@')[0]}`)"
        if isinstance(named, str)
        else "--square-mm"
    )
    return (
        f"the camera places the board {scale:.3f}x as far from pose to pose as the LiDAR measures: its "
        f"squares look {square_mm / scale:.1f} mm, not the {square_mm:g} mm given; check {check}"
    )


def _blaming(results: list[GateResult], cause: str | None) -> list[GateResult]:
    """With a ``cause``, the first failed gate's hint is it and the other failed gates' hints are dropped
    (it explains them all; "capture more poses" would not help); else the gates as they are."""
    failed = [i for i, g in enumerate(results) if not g.passed]
    if cause is None or not failed:
        return results
    return [
        g if g.passed else replace(g, hint=cause if i == failed[0] else None) for i, g in enumerate(results)
    ]


def _refuse_an_unseen_pattern(req: LidarRequest, rows: Sequence[ScanRow], named: BackingBoard | str) -> None:
    """When the board's pattern is in none of the paired images: the capture path's error (exit 2), which
    names the chessboard that is visible (a 9x6 board given for a 5x7 set), instead of "capture more"."""
    from calibctl.workflows.camera import pattern_check

    paired = [r for r in rows if r.figures is not None and r.image is not None]
    if not paired or any(r.figures is not None and r.figures.image_rms_px is not None for r in paired):
        return
    board = req.backing
    samples = []
    for r in pattern_check.spread(paired, pattern_check.PROBE_IMAGES):
        gray = _gray(req.images / str(r.image))
        if gray is not None:
            samples.append((str(r.image), gray))
    spec = BoardSpec.chessboard(board.cols, board.rows, board.square_m)
    if isinstance(named, str):
        raise pattern_check.nothing_found_error(
            spec, named, named.partition("@")[0], "images", len(paired), samples
        )
    raise pattern_check.nothing_found_error(
        spec,
        f"--cols {board.cols} --rows {board.rows}",
        "",
        f"images in {req.images}",
        len(paired),
        samples,
        given="--cols/--rows",
    )


def tf_static_yaml(result: dict[str, Any], lidar_frame: str, camera_frame: str) -> str:
    """An accepted result's T_lidar_cam (``result_json``'s document) as a tf2_msgs/TFMessage YAML (what
    `ros2 topic echo /tf_static` prints): parent ``lidar_frame``, child ``camera_frame`` (tf's transform is
    the child's pose in the parent)."""
    from calibctl.workflows.exports.rig_exports import tf_message

    t = result.get("transform")
    if result.get("status") != "accepted" or t is None:
        raise UsageError("a rejected camera-LiDAR result has no transform to export")
    w, x, y, z = t["quaternion_wxyz"]
    header = (
        f"# calibctl lidar solve T_{lidar_frame}_{camera_frame} (images {result['images']}, "
        f"scans {result['scans']})\n"
    )
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
