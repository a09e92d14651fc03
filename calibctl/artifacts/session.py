"""Capture sessions: what the camera saw, image by image, and the gates' verdict before any solve.

Sub-pixel corners are kept forever (they are ~19 kB for a 22-view session and are all a re-solve
needs); images are kept in the content-addressed image store for a retention period only.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.check import DistanceCheck
from calibctl.artifacts.common import SERIAL_PATTERN, Document, Sha256Hex, UtcDatetime

SESSION_SCHEMA_VERSION: Literal[1] = 1

ImageStatus = Literal[
    "accepted", "no_board", "bad_grid", "blurred", "near_duplicate", "wrong_size", "unreadable", "skipped"
]


class GateResult(Document):
    """One capture-time gate: its value against its threshold, and what the operator should do."""

    gate: Literal["observability", "tilt", "coverage", "views", "one_camera", "projection"] = Field(
        description="which gate"
    )
    passed: bool = Field(description="true when the gate is satisfied")
    value: float = Field(
        description="the gate's measured value (sigma5/sigma1, directions, cells, views; one_camera: the "
        "two-camera ratio, which must stay below the threshold, 0 when not checked)"
    )
    threshold: float = Field(description="the value it had to reach")
    reason: str | None = Field(
        None, description="machine-readable reason code when it failed, e.g. tilt.directions"
    )
    hint: str | None = Field(None, description="what the operator should do next, in words")
    detail: dict[str, float | int | str | list[str]] = Field(
        default_factory=dict, description="gate-specific extras (missing cells, directions seen, ...)"
    )
    advisory: bool = Field(
        False,
        exclude_if=lambda advisory: not advisory,
        description="guidance only: the projection gate decided the session, this proxy (tilt, coverage) "
        "did not",
    )


class ImageOutcome(Document):
    """What happened to one input image or video frame."""

    name: str = Field(
        description="file name (folder), path relative to the list file's or the glob's folder, "
        "or frame label"
    )
    status: ImageStatus = Field(description="accepted, or why not")
    reason: str | None = Field(None, description="why it was not accepted, in words")
    sha256: Sha256Hex | None = Field(None, description="sha256 of the image bytes (None when unreadable)")
    image_size: tuple[int, int] | None = Field(None, description="[W, H] pixels")
    corners_found: int = Field(0, ge=0, description="corners detected in this image")


class ViewCorners(Document):
    """The sub-pixel corners of one accepted view (float64, OpenCV pixel convention)."""

    name: str = Field(description="image or frame the view came from")
    image_sha256: Sha256Hex | None = Field(None, description="sha256 of that image's bytes")
    corner_ids: list[int] = Field(description="ids into the board's row-major model points")
    corners_px: list[tuple[float, float]] = Field(description="(N, 2) corner positions, pixels")
    tilt_deg: float | None = Field(None, description="angle between board normal and optical axis")
    tilt_direction: str | None = Field(None, description="which way the board faces, e.g. 'top left'")

    @model_validator(mode="after")
    def _same_length(self) -> ViewCorners:
        if len(self.corner_ids) != len(self.corners_px):
            raise ValueError(f"{len(self.corner_ids)} corner ids but {len(self.corners_px)} corners")
        return self


class MetricGauge(Document):
    """The distance gauge judged at capture (seed chapter 0): the board in a surveyed fixture, seen through
    the lens the session is solved with. A failed gauge stops the calibration unless overridden with a
    reason."""

    distance: DistanceCheck = Field(description="surveyed against recovered board distance and the verdict")
    lens_model: str = Field(description="the lens model the fixture pictures' poses were fitted through")
    reference_source: str = Field(description="the fixture pictures (folder, glob or list)")


class CaptureSession(Document):
    """One capture run for one camera serial with one board revision."""

    schema_version: Literal[1] = Field(
        SESSION_SCHEMA_VERSION, description="version of this document's schema"
    )
    session_id: str = Field(pattern=r"^[0-9a-f]{12}$", description="12 hex digits, printed by capture")
    serial: str = Field(pattern=SERIAL_PATTERN, description="camera serial number (letters, digits, . _ : -)")
    board: BoardRevision = Field(description="snapshot of the board revision used")
    source: str = Field(
        description="folder, glob pattern, list file, video file or camera the images came from"
    )
    source_kind: Literal["folder", "glob", "list", "video", "camera", "synthetic"] = Field(
        description="kind of source"
    )
    station: str = Field(description="station id")
    operator: str = Field(description="who ran the capture")
    started_at: UtcDatetime = Field(description="UTC")
    finished_at: UtcDatetime = Field(description="UTC")
    image_size: tuple[int, int] | None = Field(None, description="[W, H] shared by every accepted view")
    status: Literal["accepted", "rejected"] = Field(description="accepted when every gate passed")
    gates: list[GateResult] = Field(default_factory=list, description="capture-time gate values")
    outcomes: list[ImageOutcome] = Field(
        default_factory=list, description="one per input image or frame examined"
    )
    views: list[ViewCorners] = Field(default_factory=list, description="accepted views with their corners")
    calibctl_version: str = Field(description="calibctl version that captured")
    opencv_version: str = Field(description="OpenCV version of the detector")
    metric_gauge: MetricGauge | None = Field(
        None,
        exclude_if=lambda gauge: gauge is None,
        description="--reference-distance: the metric gauge judged at capture; absent without one (and in "
        "sessions "
        "captured before it was recorded)",
    )
