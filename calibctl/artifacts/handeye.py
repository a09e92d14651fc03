"""The hand-eye result: one rigid edge ``parent_frame -> child_frame`` of a rig tree, with its evidence.

Shaped to slot into a rig tree as an edge: ``transform`` is ``T_parent_child`` (maps points of the
child frame into the parent frame, as a ROS /tf_static edge), with one-sigma per axis, the gates
that had to pass before it was reported, per-motion residuals and where the data came from.
A rejected result (a gate failed) carries no transform: nothing unobservable or inconsistent is ever
published.
"""

from __future__ import annotations

import math
from typing import Literal, Protocol, Self

from pydantic import Field, field_validator, model_validator

from calibctl.artifacts.common import (
    CURRENT_HASH,
    LEGACY_HASH,
    Document,
    HashAlgorithm,
    Sha256Hex,
    UtcDatetime,
    content_hash,
)

HANDEYE_SCHEMA_VERSION: Literal[1] = 1
FRAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_./-]{0,127}$"
InputShape = Literal["poses", "motions", "robot-eye-in-hand", "robot-eye-to-hand"]


ROS_NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$"


class RosFrames(Document):
    """What a robot export calls an edge's two frames (``rig export --edge ... --frame SERIAL=NAME``)."""

    parent_frame: str = Field(pattern=ROS_NAME_PATTERN, description="the ROS frame of parent_frame")
    child_frame: str = Field(pattern=ROS_NAME_PATTERN, description="the ROS frame of child_frame")


def ros_frames_field() -> RosFrames | None:
    """The optional ``ros_frames`` of an edge document: set on export only, never stored or hashed."""
    return Field(
        None,
        exclude_if=lambda frames: frames is None,
        description="set by `rig export --edge FROM:TO --format json`: the ROS frames the export names "
        "parent_frame and child_frame by (the rig export's, --frame SERIAL=NAME or the defaults); not part "
        "of any content hash (the exporter's choice, like a bundle's frame names)",
    )


class RigidTransform(Document):
    """T_parent_child: the child frame's origin and axes expressed in the parent frame."""

    translation_m: tuple[float, float, float] = Field(description="child origin in the parent frame, metres")
    rotation_wxyz: tuple[float, float, float, float] = Field(
        description="unit quaternion (w, x, y, z), Hamilton, rotating child coordinates into the parent frame"
    )

    @field_validator("rotation_wxyz")
    @classmethod
    def _unit(cls, q: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        norm = sum(c * c for c in q) ** 0.5
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"rotation_wxyz must be a unit quaternion, norm is {norm:.6f}")
        return q


class EdgeUncertainty(Document):
    """One-sigma of the transform from the residual covariance of the joint refinement."""

    sigma_rotation_deg: tuple[float, float, float] = Field(
        description="about the parent's x, y, z axes, degrees"
    )
    sigma_translation_mm: tuple[float, float, float] = Field(
        description="along the parent's x, y, z axes, mm"
    )
    covariance: list[list[float]] = Field(
        description="6x6 over (rotation perturbation in the parent frame, rad; translation, m)"
    )
    residual_rotation_deg: float = Field(
        ge=0, description="RMS rotation residual component of the refinement, degrees"
    )
    residual_translation_mm: float = Field(
        ge=0, description="RMS translation residual component of the refinement, mm"
    )


class EdgeGate(Document):
    """An observability gate checked before any number is reported."""

    gate: Literal[
        "rotation", "lever-arm", "time-alignment", "consistency", "translation-scale", "metric-gauge"
    ] = Field(description="which gate (metric-gauge: the board revision's failed gauge, seed chapter 0)")
    passed: bool = Field(description="true when the gate is satisfied")
    value: float = Field(
        description="rotation about a second axis (deg), sigma_min of stacked (R_A - I), "
        "mismatched fraction, rotation residual RMS (deg), or the translation scale disagreement max(s, 1/s)"
    )
    threshold: float = Field(description="the limit it was judged against")
    message: str = Field(description="what was measured, in words")
    hint: str | None = Field(None, description="what to do when it failed")
    detail: dict[str, float | int | str | list[str]] = Field(default_factory=dict, description="gate extras")


class GateOutcome(Protocol):
    """What a core gate result (core.lidar.gates, core.imu.gates) carries into a ``SolveGate``."""

    @property
    def gate(self) -> str: ...
    @property
    def passed(self) -> bool: ...
    @property
    def value(self) -> float | None: ...
    @property
    def threshold(self) -> float: ...
    @property
    def message(self) -> str: ...
    @property
    def hint(self) -> str | None: ...


class SolveGate(Document):
    """One gate of a sensor edge's solve (the LiDAR and camera-IMU edges), before or after the solve; each
    kind names its gates in its own ``gate`` description."""

    gate: str = Field(description="the gate's name")
    passed: bool = Field(description="true when satisfied")
    value: float | None = Field(
        description="what was measured (unit in the message); none when not computable"
    )
    threshold: float = Field(description="the limit it was judged against")
    message: str = Field(description="the verdict in words")
    hint: str | None = Field(None, description="what to capture or check next when it failed")

    @classmethod
    def from_result(cls, g: GateOutcome) -> Self:
        """The stored form of a core gate result; a value that could not be computed (NaN, inf) as None."""
        value = None if g.value is None or not math.isfinite(g.value) else float(g.value)
        return cls(
            gate=g.gate, passed=g.passed, value=value, threshold=g.threshold, message=g.message, hint=g.hint
        )


class MotionResidual(Document):
    """One motion (a pair of synchronised relative motions of the two frames)."""

    label: str = Field(description="which rows or images the motion spans")
    angle_parent_deg: float = Field(ge=0, description="rotation angle of the parent sensor's motion, degrees")
    angle_child_deg: float = Field(ge=0, description="rotation angle of the child sensor's motion, degrees")
    angle_mismatch_deg: float = Field(
        description="parent angle - child angle (0 for a synchronised pair), degrees"
    )
    residual_rotation_deg: float | None = Field(
        None, ge=0, description="|rotation misfit| of A X = X B, degrees"
    )
    residual_translation_mm: float | None = Field(
        None, ge=0, description="|translation misfit| of A X = X B, mm"
    )
    outlier: bool = Field(False, description="residual above 4 robust sigmas")


class EdgeProvenance(Document):
    calibctl_version: str = Field(description="calibctl version that produced the result")
    opencv_version: str = Field(description="OpenCV version")
    station: str = Field(description="station id")
    operator: str = Field(description="who ran it")
    created_at: UtcDatetime = Field(description="UTC time of the solve")
    input_file: str = Field(description="name of the motions/poses CSV")
    input_sha256: Sha256Hex = Field(description="sha256 of that CSV")
    input_shape: InputShape = Field(description="poses, motions, robot-eye-in-hand or robot-eye-to-hand")
    camera: str | None = Field(
        None, description="SERIAL@VERSION whose intrinsics gave the board poses (robot case)"
    )
    board: str | None = Field(None, description="NAME@REVISION of the board (robot case)")
    input_image_sha256: list[Sha256Hex] = Field(
        default_factory=list, description="sha256 of every image used"
    )


class HandEyeResult(Document):
    """One hand-eye solve of the edge parent_frame -> child_frame."""

    schema_version: Literal[1] = Field(
        HANDEYE_SCHEMA_VERSION, description="version of this document's schema"
    )
    kind: Literal["handeye"] = Field("handeye", description="document kind")
    parent_frame: str = Field(pattern=FRAME_PATTERN, description="frame A of A X = X B (the tf parent)")
    child_frame: str = Field(pattern=FRAME_PATTERN, description="frame B of A X = X B (the tf child)")
    status: Literal["accepted", "rejected"] = Field(description="accepted only when every gate passed")
    method: Literal["park", "tsai"] = Field(description="closed-form start before the joint refinement")
    transform: RigidTransform | None = Field(description="T_parent_child; null when rejected")
    refinement: Literal["motions", "poses"] | None = Field(
        None,
        description="residual model of the joint refinement: per motion, or per pose (AX = YB); null when "
        "rejected",
    )
    uncertainty: EdgeUncertainty | None = Field(description="one-sigma; null when rejected or not estimable")
    uncertainty_refused_reason: str | None = Field(None, description="why no uncertainty is reported")
    gates: list[EdgeGate] = Field(
        description="observability gates (before the solve), the consistency and translation-scale gates "
        "(after)"
    )
    lever_arm_singular_values: tuple[float, float, float] = Field(
        description="singular values of stacked (R_A - I)"
    )
    motions: list[MotionResidual] = Field(description="per-motion angles and residuals")
    outlier_motions: list[str] = Field(
        default_factory=list, description="labels of motions named as outliers"
    )
    skipped: list[str] = Field(default_factory=list, description="inputs left out, each with its reason")
    provenance: EdgeProvenance = Field(description="how, where, when and from what it was made")
    ros_frames: RosFrames | None = ros_frames_field()
    content_hash_algorithm: HashAlgorithm = Field(
        LEGACY_HASH,
        exclude_if=lambda algorithm: algorithm == LEGACY_HASH,
        description="how content_sha256 is computed: sha256-rfc8785 = sha256 of the RFC 8785 (JCS) form of "
        "every "
        "other field, this one included; absent = sha256-python-json, the results written before it",
    )
    content_sha256: Sha256Hex = Field(description="sha256 of the canonical JSON of every other field")

    @model_validator(mode="after")
    def _consistent(self) -> HandEyeResult:
        if self.parent_frame == self.child_frame:
            raise ValueError("parent_frame and child_frame must differ")
        if self.status == "accepted" and (self.transform is None or not all(g.passed for g in self.gates)):
            raise ValueError("an accepted result needs a transform and every gate passed")
        if self.status == "rejected" and self.transform is not None:
            raise ValueError("a rejected result carries no transform")
        return self

    def computed_sha256(self) -> str:
        """The hash under the result's own ``content_hash_algorithm`` (old results keep theirs)."""
        return content_hash(self, {"content_sha256", "ros_frames"}, self.content_hash_algorithm)

    def sealed(self) -> HandEyeResult:
        """A copy hashed with the current algorithm (RFC 8785)."""
        current = self.model_copy(update={"content_hash_algorithm": CURRENT_HASH})
        return current.model_copy(update={"content_sha256": current.computed_sha256()})
