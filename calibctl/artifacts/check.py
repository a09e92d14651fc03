"""A re-test of a stored calibration on fresh board views (``calibctl check``): an event in the serial's
history.

The calibration itself is never changed: the check records which version it tested, on what, the
numbers and the verdict. Stored immutable (triggers of revision 0006) with the sha256 of its payload.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from calibctl.artifacts.common import SERIAL_PATTERN, Document, UtcDatetime

CHECK_SCHEMA_VERSION: Literal[1] = 1


class RegionCheck(Document):
    """Fresh RMS against the calibration's held-out RMS in one region (overall, a radius ring, an octant)."""

    region: str = Field(description="overall, ring 1..5 (inner to outer) or octant 0..7")
    check_rms_px: float | None = Field(None, ge=0, description="RMS of the fresh residuals, pixels")
    reference_rms_px: float | None = Field(
        None, ge=0, description="the calibration's held-out RMS there, pixels"
    )
    ratio: float | None = Field(None, ge=0, description="check / reference; absent when not tested")
    limit: float = Field(gt=0, description="largest ratio that passes")
    corners: int = Field(ge=0, description="fresh corners in the region")
    tested: bool = Field(description="enough corners on both sides to test")
    passed: bool = Field(description="not tested, or ratio <= limit")


class ShiftCheck(Document):
    """How far the fresh views pull one intrinsic from the stored value (measured, never applied)."""

    parameter: Literal["focal", "cx", "cy"] = Field(description="focal (relative, both fx and fy) or cx/cy")
    shift: float = Field(description="focal: relative (0.005 = +0.5 %); cx, cy: pixels")
    sigma: float = Field(gt=0, description="one-sigma of the shift: fresh estimate and stored sigma combined")
    z_limit: float = Field(gt=0, description="largest |shift / sigma| that passes")
    passed: bool = Field(description="|shift / sigma| <= z_limit")


class DistanceCheck(Document):
    """The gauge at the station: the board held at a surveyed distance (seed chapter 0)."""

    reference_m: float = Field(gt=0, description="surveyed camera-to-board-centre distance, metres")
    reference_sigma_m: float = Field(ge=0, description="its one-sigma, metres")
    recovered_m: float = Field(gt=0, description="median recovered distance over the views, metres")
    spread: float = Field(ge=0, description="(max - min) / median of the recovered distances")
    ratio: float = Field(gt=0, description="recovered / reference")
    ratio_limits: tuple[float, float] = Field(description="the ratio must lie within these")
    passed: bool = Field(description="ratio within the limits")


class CheckEvent(Document):
    """One re-test of one calibration version. Never updated, never deleted."""

    schema_version: Literal[1] = Field(CHECK_SCHEMA_VERSION, description="version of this document's schema")
    check_id: str = Field(pattern=r"^[0-9a-f]{12}$", description="random id of this check")
    serial: str = Field(pattern=SERIAL_PATTERN, description="camera serial number")
    version: int = Field(ge=1, description="the calibration version that was tested")
    calibration_sha256: str = Field(pattern=r"^[0-9a-f]{64}$", description="content_sha256 of that version")
    source: str = Field(description="where the fresh images came from")
    station: str = Field(description="station id")
    operator: str = Field(description="who ran it")
    at: UtcDatetime = Field(description="UTC time of the check")
    image_size: tuple[int, int] = Field(description="[W, H] of the fresh images (equal to the calibration's)")
    images: int = Field(ge=0, description="image files examined")
    views: list[str] = Field(description="images whose board was detected and used")
    view_rms_px: list[float] = Field(description="per-view RMS under the stored model, pixels")
    regions: list[RegionCheck] = Field(description="overall first, then radius rings, then octants")
    shifts: list[ShiftCheck] = Field(
        default_factory=list, description="focal, cx, cy pulls; empty if unconstrained"
    )
    distance: DistanceCheck | None = Field(None, description="present with --reference-distance")
    alpha: float = Field(gt=0, lt=1, description="false-fail probability the limits are set for")
    passed: bool = Field(description="every test passed")
    reasons: list[str] = Field(default_factory=list, description="what failed, in words")
    not_judged: list[str] | None = Field(
        None,
        exclude_if=lambda parts: parts is None,
        description="what this check could not judge, and why (a fixture check of a few pictures of one pose "
        "judges the metric gauge alone: the statistical re-test needs 10 views); absent when every part ran, "
        "and in checks made before it was recorded",
    )
