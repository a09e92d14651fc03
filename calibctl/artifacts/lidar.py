"""The camera-LiDAR result as evidence of a rig-tree edge ``lidar_frame -> camera`` (docs/lidar.md).

``calibctl lidar solve ... --rig RIG`` stores it inside the rig's next version (``RigCalibration.lidar``),
so it is part of that version's sealed content: T_lidar_cam with its 6x6 covariance, every gate, every
scan's outcome and the held-out figures. A rejected result keeps its gates and outcomes but adds no edge
(``transform`` may still hold the rejected estimate: the rig tree never carries it).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from calibctl.artifacts.common import SERIAL_PATTERN, Document, Sha256Hex, UtcDatetime
from calibctl.artifacts.handeye import FRAME_PATTERN, RosFrames, SolveGate, ros_frames_field

LIDAR_SCHEMA_VERSION: Literal[1] = 1
ScanOutcome = Literal[
    "accepted", "no_plane", "too_few_rings", "dimension_mismatch", "no_board_in_image", "not_paired"
]
Matrix4 = tuple[tuple[float, float, float, float], ...]


class LidarGate(SolveGate):
    """One gate of the camera-LiDAR solve (core.lidar.gates), before or after the solve."""

    gate: str = Field(
        description="lidar-poses, lidar-observability, lidar-range-spread, lidar-plane-rms, "
        "lidar-dimension or lidar-held-out"
    )


class LidarScan(Document):
    """One scan's (or unpaired image's) outcome."""

    frame: int | None = Field(description="frame number (the last number of the file name)")
    image: str | None = Field(description="image file name")
    scan: str | None = Field(description="scan file name")
    outcome: ScanOutcome = Field(description="what became of it")
    message: str = Field(description="why, with the numbers")


class LidarTransform(Document):
    """T_lidar_cam: p_lidar = R p_cam + t, with its one-sigma."""

    T_lidar_cam: Matrix4 = Field(description="4x4, maps camera-frame points into the LiDAR frame, metres")
    quaternion_wxyz: tuple[float, float, float, float] = Field(
        description="rotation of T_lidar_cam (w, x, y, z)"
    )
    rpy_rad: tuple[float, float, float] = Field(
        description="roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll)"
    )
    sigma_translation_mm: tuple[float, float, float] = Field(description="along LiDAR x, y, z, mm")
    sigma_rotation_deg: tuple[float, float, float] = Field(description="about LiDAR x, y, z, degrees")
    covariance: list[list[float]] = Field(
        description="6x6 over rotation about LiDAR x, y, z (rad; left "
        "perturbation) and translation x, y, z (m)"
    )


class LidarMetrics(Document):
    """Fit and held-out figures of an accepted (or post-gate rejected) solve."""

    poses: int = Field(ge=0, description="accepted poses used")
    plane_rms_mm: float = Field(description="point-to-plane RMS, mm")
    edge_rms_mm: float = Field(description="ring end points to the backing board's outline, RMS mm")
    projected_edge_rms_px: float | None = Field(description="that edge error in the image, RMS px")
    held_out_plane_rms_mm: float | None = Field(description="k-fold held-out point-to-plane RMS, mm")
    held_out_edge_rms_mm: float | None = Field(description="k-fold held-out edge RMS, mm")
    held_out_projected_edge_rms_px: float | None = Field(
        None, description="k-fold held-out edge RMS in the image, px"
    )
    folds: int = Field(ge=0, description="k of the k-fold")
    dimension_error_mean_mm: tuple[float, float] = Field(description="mean board width, height error, mm")
    range_offset_from_dimensions_mm: float | None = Field(
        description="range offset the board sizes ask for, mm"
    )


class LidarOverlaySource(Document):
    """The first accepted pose's files, pinned by hash: what the report draws the sweep over."""

    image_path: str = Field(description="the image as read at solve time (absolute path)")
    image_sha256: Sha256Hex = Field(description="its sha256")
    scan_path: str = Field(description="the sweep as read at solve time (absolute path)")
    scan_sha256: Sha256Hex = Field(description="its sha256")
    scan_scale_to_m: float = Field(gt=0, description="1 (metres) or 0.001 (a sweep written in mm)")


class LidarEdgeResult(Document):
    """One camera-LiDAR solve of the edge ``parent_frame`` (the LiDAR) -> ``child_frame`` (a rig camera)."""

    schema_version: Literal[1] = Field(LIDAR_SCHEMA_VERSION, description="version of this document's schema")
    kind: Literal["lidar"] = Field("lidar", description="document kind")
    parent_frame: str = Field(
        pattern=FRAME_PATTERN, description="the LiDAR frame (a ROS name declared in the rig)"
    )
    child_frame: str = Field(pattern=SERIAL_PATTERN, description="the camera: a rig member's serial")
    status: Literal["accepted", "rejected"] = Field(description="accepted when every gate passed")
    camera: str = Field(description="SERIAL@VERSION whose calibration gave the board poses")
    board: str = Field(description="NAME@REVISION of the board, or the dimensions given on the command line")
    images: str = Field(description="the images folder as given")
    scans: str = Field(description="the scans folder as given")
    box: tuple[float, float, float, float, float, float] = Field(
        description="station box, metres, LiDAR frame"
    )
    range_offset_applied_mm: float = Field(description="--range-offset-mm applied before segmentation")
    transform: LidarTransform | None = Field(
        description="the estimate (none when a gate refused the set first)"
    )
    metrics: LidarMetrics | None = Field(description="fit and held-out figures (none without a transform)")
    gates: list[LidarGate] = Field(description="every gate, in order")
    scans_outcomes: list[LidarScan] = Field(description="one outcome per scan or unpaired image")
    overlay: LidarOverlaySource | None = Field(None, description="files the report overlay is drawn from")
    created_at: UtcDatetime = Field(description="UTC time of the solve")
    ros_frames: RosFrames | None = ros_frames_field()
