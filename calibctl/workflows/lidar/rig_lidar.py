"""A LiDAR is a frame of the robot's tree: ``calibctl lidar solve ... --rig RIG --serial CAM --lidar-frame NAME``.

The same shape as ``handeye --rig`` (workflows.handeye.rig_edges, whose machinery this reuses): the
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
from typing import Any

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
from calibctl.artifacts.rig import RigEdge
from calibctl.config import Settings
from calibctl.errors import NotFoundError, UsageError
from calibctl.workflows.exports.frame_names import is_ros_name
from calibctl.workflows.handeye import rig_edges
from calibctl.workflows.handeye.rig_edges import LIDAR, StoredEdge
from calibctl.workflows.lidar.lidar_solve import LidarRequest
from calibctl.workflows.store_admin.records import open_store

ROS_NAME_RULE = "ROS names are [a-zA-Z][a-zA-Z0-9_]* segments separated by '/' (no '-', no leading '/')"


def check_target(settings: Settings, rig_name: str, lidar_frame: str, serial: str | None) -> None:
    """Before any solve (exit 2; module docstring)."""
    if serial is None:
        raise UsageError(
            "--rig needs --serial CAMERA: the rig member whose active calibration poses the board",
            "the edge pins that calibration (not a camera_info file)",
        )
    if not is_ros_name(lidar_frame):
        raise UsageError(f"--lidar-frame '{lidar_frame}' is not a legal ROS frame name", ROS_NAME_RULE)
    with open_store(settings) as store:
        rig = store.get_rig(rig_name)
        if serial not in rig.cameras:
            raise NotFoundError(
                f"camera {serial} is not a member of rig {rig_name} (members {', '.join(rig.cameras)})",
                f"pass --serial with one of them, or `calibctl rig add` a rig with {serial} in it",
            )
        if lidar_frame in rig.cameras:
            raise UsageError(
                f"--lidar-frame {lidar_frame} is a camera of rig {rig_name}",
                "name the LiDAR's own frame, declared with `calibctl rig add ... --frame NAME`",
            )
        rig_edges.checked(store, rig_name, lidar_frame, serial, None, LIDAR)


def _sha256(path: Path) -> str:
    with files.file_errors("read", path):
        return hashlib.sha256(path.read_bytes()).hexdigest()


def _overlay_source(req: LidarRequest, rows: list[dict[str, Any]]) -> LidarOverlaySource | None:
    first = next((r for r in rows if r["outcome"] == "accepted"), None)
    if first is None:
        return None
    image, scan = (req.images / first["image"]).resolve(), (req.scans / first["scan"]).resolve()
    return LidarOverlaySource(
        image_path=str(image),
        image_sha256=_sha256(image),
        scan_path=str(scan),
        scan_sha256=_sha256(scan),
        scan_scale_to_m=req.scan_scale_to_m,
    )


def evidence(
    result: dict[str, Any], req: LidarRequest, lidar_frame: str, serial: str, board: str
) -> LidarEdgeResult:
    """``lidar_solve.run_lidar_solve``'s result as the rig version's evidence."""
    t, m = result.get("transform"), result.get("metrics")
    transform = (
        None
        if t is None
        else LidarTransform(
            T_lidar_cam=tuple(tuple(row) for row in t["matrix"]),
            quaternion_wxyz=tuple(t["quaternion_wxyz"]),
            rpy_rad=tuple(t["rpy_rad"]),
            sigma_translation_mm=tuple(t["sigma_translation_mm"]),
            sigma_rotation_deg=tuple(t["sigma_rotation_deg"]),
            covariance=t["covariance"],
        )
    )
    metrics = None if m is None else LidarMetrics(**{k: m[k] for k in LidarMetrics.model_fields})
    box = req.box
    return LidarEdgeResult(
        parent_frame=lidar_frame,
        child_frame=serial,
        status=result["status"],
        camera=result["lens"],
        board=board,
        images=str(req.images),
        scans=str(req.scans),
        box=(*box.lower_m, *box.upper_m),
        range_offset_applied_mm=result["range_offset_applied_mm"],
        transform=transform,
        metrics=metrics,
        gates=[LidarGate(**{k: g[k] for k in LidarGate.model_fields}) for g in result["gates"]],
        scans_outcomes=[LidarScan(**{k: r[k] for k in LidarScan.model_fields}) for r in result["outcomes"]],
        overlay=_overlay_source(req, result["outcomes"]) if t is not None else None,
        created_at=utc_now(),
    )


def lidar_edge(ev: LidarEdgeResult) -> RigEdge:
    """An accepted result as the tree edge ``lidar_frame -> camera`` (T_lidar_cam)."""
    assert ev.transform is not None
    return rig_edges.tree_edge(
        ev.parent_frame,
        ev.child_frame,
        np.array(ev.transform.T_lidar_cam),
        np.array(ev.transform.covariance),
        LIDAR.source,
    )


def store_lidar(settings: Settings, rig_name: str, ev: LidarEdgeResult) -> StoredEdge:
    """Store ``ev`` as the rig's next version; active only when accepted (and lint-clean)."""
    edge = lidar_edge(ev) if ev.status == "accepted" and ev.transform is not None else None
    return rig_edges.store_evidence(
        settings,
        rig_name,
        ev,
        lambda base, versions: rig_edges.with_evidence(base, ev, edge, versions, settings),
    )
