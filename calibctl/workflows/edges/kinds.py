"""The table of evidence-edge kinds: everything that differs between a hand-eye and a camera-LiDAR edge.

Generic code (``versions``, ``export``) looks a kind up here (``kind_of``, ``KINDS``) and never switches on
the evidence type; a new sensor is one more ``EdgeKind`` entry (package docstring).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibctl.artifacts.handeye import HandEyeResult
from calibctl.artifacts.imu import ImuEdgeResult
from calibctl.artifacts.lidar import LidarEdgeResult
from calibctl.artifacts.rig import Matrix4, RigCalibration, RigEdge
from calibctl.core.extrinsics import se3
from calibctl.errors import UsageError
from calibctl.workflows.edges.tree import tree_edge

Evidence = HandEyeResult | LidarEdgeResult | ImuEdgeResult
Frames = Mapping[str, str] | None


@dataclass(frozen=True)
class EdgeKind:
    """One kind of evidence edge. The callables take that kind's evidence."""

    source: str  # RigEdge.source
    label: str  # the kind in a sentence ("no hand-eye or LiDAR edge")
    evidence_field: str  # the RigCalibration field its evidence lives in
    evidence: type  # the evidence document
    frames: str  # parent -> child, in words
    covariance_layout: str  # the order of the solver's 6x6 covariance
    rule: str  # lint rule prefix
    rerun: str  # the command that puts the edge back
    command: str  # what the user runs, for "solve the rig first, then ..."
    camera_ref: Callable[[Any], str | None]  # SERIAL@VERSION of the camera it was solved with
    tree_edge: Callable[[Any], RigEdge]  # an accepted result as a tree edge, with its covariance
    no_sigma: Callable[[Any], str | None]  # why an accepted result has no usable one-sigma, or None
    sigmas: Callable[[Any], tuple[float, float] | None]  # largest one-sigma: translation mm, rotation deg
    tf: Callable[[Any, RigCalibration, Frames], str]  # the edge as /tf_static YAML, frames renamed
    loose_translation_mm: float | None = None  # above either: a loose-sigma warning
    loose_rotation_deg: float | None = None
    loose_fix: str = ""


def handeye_tf_yaml(result: HandEyeResult, frames: Frames = None) -> str:
    """The edge as a tf2_msgs/TFMessage YAML (what `ros2 topic echo /tf_static` prints); ``frames`` renames
    its two frames (a rig export's robot frame names, workflows.exports.frame_names)."""
    if result.transform is None:
        raise UsageError("a rejected hand-eye result has no transform to export")
    from calibctl.workflows.exports.rig_exports import tf_message

    w, x, y, z = result.transform.rotation_wxyz
    header = (
        f"# calibctl handeye {result.parent_frame} -> {result.child_frame} sha256 {result.content_sha256}\n"
    )
    name = (frames or {}).get
    return header + tf_message(
        [
            (
                name(result.parent_frame) or result.parent_frame,
                name(result.child_frame) or result.child_frame,
                result.transform.translation_m,
                (x, y, z, w),
            )
        ]
    )


def _handeye_edge(result: HandEyeResult) -> RigEdge:
    assert result.transform is not None and result.uncertainty is not None
    R = se3.rotation_from_quaternion(np.array(result.transform.rotation_wxyz))
    T = se3.transform(R, list(result.transform.translation_m))
    return tree_edge(
        result.parent_frame, result.child_frame, T, np.array(result.uncertainty.covariance), "hand-eye"
    )


def _handeye_sigmas(result: HandEyeResult) -> tuple[float, float] | None:
    u = result.uncertainty
    return None if u is None else (max(u.sigma_translation_mm), max(u.sigma_rotation_deg))


def _lidar_edge(ev: LidarEdgeResult) -> RigEdge:
    assert ev.transform is not None
    return tree_edge(
        ev.parent_frame,
        ev.child_frame,
        np.array(ev.transform.T_lidar_cam),
        np.array(ev.transform.covariance),
        "lidar-board",
    )


def _lidar_no_sigma(ev: LidarEdgeResult) -> str | None:
    if ev.transform is None:
        return "no transform"
    if not np.all(np.linalg.eigvalsh(np.array(ev.transform.covariance)) > 0):
        return "the 6x6 covariance is not positive definite"
    return None


def _lidar_sigmas(ev: LidarEdgeResult) -> tuple[float, float] | None:
    t = ev.transform
    return None if t is None else (max(t.sigma_translation_mm), max(t.sigma_rotation_deg))


def _published_tf(
    word: str, parent: str, child: str, T: Matrix4 | None, accepted: bool, cal: RigCalibration, frames: Frames
) -> str:
    """An evidence edge's T_parent_child as /tf_static YAML, its frames renamed by ``frames``; UsageError
    for a rejected result (no transform is published)."""
    from calibctl.workflows.exports.rig_exports import tf_message

    if T is None or not accepted:
        raise UsageError(
            f"the {word} result {parent} -> {child} of {cal.rig}@{cal.version} was rejected: no transform "
            "is published"
        )
    w, x, y, z = se3.quaternion_from_rotation(np.array(T)[:3, :3])
    name = (frames or {}).get
    t = [row[3] for row in T[:3]]
    return (
        f"# calibctl {word.lower()} {parent} -> {child} of rig {cal.rig}@{cal.version} "
        f"sha256 {cal.content_sha256}\n"
        + tf_message([(name(parent) or parent, name(child) or child, t, (x, y, z, w))])
    )


def _lidar_tf(ev: LidarEdgeResult, cal: RigCalibration, frames: Frames) -> str:
    T = None if ev.transform is None else ev.transform.T_lidar_cam
    return _published_tf("LiDAR", ev.parent_frame, ev.child_frame, T, ev.status == "accepted", cal, frames)


def _imu_edge(ev: ImuEdgeResult) -> RigEdge:
    assert ev.estimate is not None
    cov = np.array(ev.estimate.covariance)[:6, :6]  # (rotation, translation); td stays in the evidence
    return tree_edge(ev.parent_frame, ev.child_frame, np.array(ev.estimate.T_imu_cam), cov, "camera-imu")


def _imu_no_sigma(ev: ImuEdgeResult) -> str | None:
    if ev.estimate is None:
        return "no estimate"
    if not np.all(np.linalg.eigvalsh(np.array(ev.estimate.covariance)[:6, :6]) > 0):
        return "the (rotation, translation) block of the covariance is not positive definite"
    return None


def _imu_sigmas(ev: ImuEdgeResult) -> tuple[float, float] | None:
    e = ev.estimate
    return None if e is None else (max(e.sigma_translation_mm), max(e.sigma_rotation_deg))


def _imu_tf(ev: ImuEdgeResult, cal: RigCalibration, frames: Frames) -> str:
    T = None if ev.estimate is None else ev.estimate.T_imu_cam
    return _published_tf("IMU", ev.parent_frame, ev.child_frame, T, ev.status == "accepted", cal, frames)


HANDEYE = EdgeKind(
    source="hand-eye",
    label="hand-eye",
    evidence_field="handeye",
    evidence=HandEyeResult,
    frames="flange (or imu, base) -> camera: X = T_parent_child of A X = X B",
    covariance_layout="rotation about parent x, y, z (rad), translation x, y, z (m); left perturbation",
    rule="handeye",
    rerun="calibctl handeye ... --rig",
    command="handeye",
    camera_ref=lambda ev: ev.provenance.camera,
    tree_edge=_handeye_edge,
    no_sigma=lambda ev: (
        None if ev.uncertainty is not None else (ev.uncertainty_refused_reason or "not estimable")
    ),
    sigmas=_handeye_sigmas,
    tf=lambda ev, cal, frames: handeye_tf_yaml(ev, frames),
)
# loose-edge warnings of a LiDAR edge: sigmas a station set of 10+ varied poses stays well under
LIDAR = EdgeKind(
    source="lidar-board",
    label="LiDAR",
    evidence_field="lidar",
    evidence=LidarEdgeResult,
    frames="lidar -> camera: T_lidar_cam, p_lidar = R p_cam + t",
    covariance_layout="rotation about LiDAR x, y, z (rad), translation x, y, z (m); left perturbation",
    rule="lidar",
    rerun="calibctl lidar solve ... --rig",
    command="lidar solve",
    camera_ref=lambda ev: ev.camera,
    tree_edge=_lidar_edge,
    no_sigma=_lidar_no_sigma,
    sigmas=_lidar_sigmas,
    tf=_lidar_tf,
    loose_translation_mm=10.0,
    loose_rotation_deg=0.5,
    loose_fix="add poses nearer the LiDAR and tilted further",
)
# loose-edge warnings of an IMU edge: a 60 s dance with rate reversals on every axis stays well under
IMU = EdgeKind(
    source="camera-imu",
    label="camera-IMU",
    evidence_field="imu",
    evidence=ImuEdgeResult,
    frames="imu -> camera: T_imu_cam, p_imu = R p_cam + t; td_s (t_imu = t_cam + td_s) in the evidence",
    covariance_layout="rotation about IMU x, y, z (rad), translation x, y, z (m); left perturbation "
    "(the first 6x6 block of the evidence's 7x7, whose last row and column are td)",
    rule="imu",
    rerun="calibctl imu solve ... --rig",
    command="imu solve",
    camera_ref=lambda ev: ev.camera,
    tree_edge=_imu_edge,
    no_sigma=_imu_no_sigma,
    sigmas=_imu_sigmas,
    tf=_imu_tf,
    loose_translation_mm=10.0,
    loose_rotation_deg=0.5,
    loose_fix="record again with rate reversals on every axis and the board near and filling the image",
)
KINDS: tuple[EdgeKind, ...] = (HANDEYE, LIDAR, IMU)
EVIDENCE_SOURCES = tuple(k.source for k in KINDS)
# the lint rules saying a version was solved with a camera calibration that is no longer active
STALE_RULES = ("rig-stale-member", *(f"{k.rule}-stale-member" for k in KINDS))


def kind_of(ev: object) -> EdgeKind:
    """The kind whose evidence ``ev`` is; UsageError for a type no kind holds."""
    for k in KINDS:
        if isinstance(ev, k.evidence):
            return k
    raise UsageError(
        f"{type(ev).__name__} is not the evidence of any rig edge kind",
        hint=f"the kinds are {', '.join(k.source for k in KINDS)} (workflows.edges.kinds.KINDS)",
    )


def evidence_of(cal: RigCalibration) -> list[Evidence]:
    """Every evidence document of ``cal``, kind by kind in table order."""
    return [ev for k in KINDS for ev in getattr(cal, k.evidence_field)]


def camera_ref(ev: Evidence) -> str | None:
    """SERIAL@VERSION of the camera calibration the evidence was solved with, when it names one."""
    return kind_of(ev).camera_ref(ev)


def evidence_camera(ev: Evidence) -> tuple[str, int] | None:
    """(serial, version) of ``camera_ref``."""
    ref = camera_ref(ev)
    if not ref or "@" not in ref:
        return None
    serial, _, version = ref.rpartition("@")
    return (serial, int(version)) if version.isdigit() else None


def evidence_cameras(results: list[Evidence]) -> list[str]:
    return [c[0] for c in map(evidence_camera, results) if c is not None]
