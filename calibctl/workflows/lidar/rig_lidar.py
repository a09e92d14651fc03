"""A LiDAR is a frame of the robot's tree:
``calibctl lidar solve ... --rig RIG --serial CAM --lidar-frame NAME``.

The same shape as ``handeye --rig`` (the ``edges`` room's machinery and its ``LIDAR`` kind): the
gated result becomes the rig's next immutable version = the active version's edges with
``NAME -> CAM`` (``source: "lidar-board"``, T_lidar_cam) added or replaced, and the result's summary
(T, 6x6 covariance, gates, every scan's outcome, held-out figures; ``RigCalibration.lidar``) sealed
inside it; written compare-and-set on the base version. A rejected result is stored as a rejected
version (never active) carrying its evidence and no edge, and the command exits 1.

Refused before any scan is read (exit 2, nothing stored): an unknown rig or one without an active
version, a ``--lidar-frame`` that is no legal ROS name or not declared in the rig (``rig add ... --frame``),
a camera that is not a member, a camera without an active calibration, an edge that would close a loop.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from calibctl import files
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.lidar import (
    LidarEdgeResult,
    LidarGate,
    LidarMetrics,
    LidarOverlaySource,
    LidarScan,
    LidarTransform,
)
from calibctl.config import Settings
from calibctl.workflows.edges import versions
from calibctl.workflows.edges.kinds import LIDAR
from calibctl.workflows.edges.versions import StoredEdge
from calibctl.workflows.lidar.lidar_solve import LidarOutcome, LidarRequest, ScanRow


def check_target(settings: Settings, rig_name: str, lidar_frame: str, serial: str | None) -> None:
    """Before any solve (exit 2; module docstring)."""
    versions.check_sensor_target(settings, rig_name, lidar_frame, serial, LIDAR, "--lidar-frame")


def _sha256(path: Path) -> str:
    with files.file_errors("read", path):
        return hashlib.sha256(path.read_bytes()).hexdigest()


def _overlay_source(req: LidarRequest, rows: list[ScanRow]) -> LidarOverlaySource | None:
    first = next((r for r in rows if r.outcome == "accepted" and r.image and r.scan), None)
    if first is None or first.image is None or first.scan is None:
        return None
    image, scan = (req.images / first.image).resolve(), (req.scans / first.scan).resolve()
    return LidarOverlaySource(
        image_path=str(image),
        image_sha256=_sha256(image),
        scan_path=str(scan),
        scan_sha256=_sha256(scan),
        scan_scale_to_m=req.scan_scale_to_m,
    )


def _or_none(v: float | None) -> float | None:
    """A figure that could not be computed (NaN, inf) as None, as the JSON writes it."""
    return None if v is None or not np.isfinite(v) else float(v)


def evidence(
    outcome: LidarOutcome, req: LidarRequest, lidar_frame: str, serial: str, board: str
) -> LidarEdgeResult:
    """``lidar_solve.run_lidar_solve``'s typed result as the rig version's evidence, at full precision."""
    fit, m = outcome.fit, outcome.metrics
    transform = (
        None
        if fit is None
        else LidarTransform(
            T_lidar_cam=tuple(tuple(float(v) for v in row) for row in fit.T_lidar_cam),
            quaternion_wxyz=fit.quaternion_wxyz,
            rpy_rad=fit.rpy_rad,
            sigma_translation_mm=fit.sigma_translation_mm,
            sigma_rotation_deg=fit.sigma_rotation_deg,
            covariance=[[float(v) for v in row] for row in fit.covariance],
        )
    )
    metrics = (
        None
        if m is None
        else LidarMetrics(
            poses=m.poses,
            plane_rms_mm=m.plane_rms_mm,
            edge_rms_mm=m.edge_rms_mm,
            projected_edge_rms_px=_or_none(m.projected_edge_rms_px),
            held_out_plane_rms_mm=_or_none(m.held_out_plane_rms_mm),
            held_out_edge_rms_mm=_or_none(m.held_out_edge_rms_mm),
            held_out_projected_edge_rms_px=_or_none(m.held_out_projected_edge_rms_px),
            folds=m.folds,
            dimension_error_mean_mm=m.dimension_error_mean_mm,
            range_offset_from_dimensions_mm=_or_none(m.range_offset_from_dimensions_mm),
        )
    )
    box = req.box
    return LidarEdgeResult(
        parent_frame=lidar_frame,
        child_frame=serial,
        status=outcome.status,
        camera=outcome.lens,
        board=board,
        images=str(req.images),
        scans=str(req.scans),
        box=(*box.lower_m, *box.upper_m),
        range_offset_applied_mm=outcome.range_offset_applied_mm,
        transform=transform,
        metrics=metrics,
        gates=[LidarGate.from_result(g) for g in outcome.gates],
        scans_outcomes=[
            LidarScan.model_validate(
                {
                    "frame": r.frame,
                    "image": r.image,
                    "scan": r.scan,
                    "outcome": r.outcome,
                    "message": r.message,
                }
            )
            for r in outcome.rows
        ],
        overlay=_overlay_source(req, outcome.rows) if fit is not None else None,
        created_at=utc_now(),
    )


def store_lidar(settings: Settings, rig_name: str, ev: LidarEdgeResult) -> StoredEdge:
    """Store ``ev`` as the rig's next version; active only when accepted (and lint-clean)."""
    return versions.store_evidence(settings, rig_name, ev)
