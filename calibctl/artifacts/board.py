"""Board revisions: the pattern geometry plus the *measured* square size and its provenance.

The square size is the one metric input of an intrinsic calibration (seed chapter 0): it scales every
translation the robot will ever report and leaves no residual when it is wrong. So it is recorded as
a measurement (value, one-sigma uncertainty, instrument, who, when, evidence hash), never as a bare
number. A board registered without one is ``nominal`` and every calibration made with it fails lint.
Revisions are immutable; re-measuring a board creates the next revision.
"""

from __future__ import annotations

import datetime as dt
import re
from typing import Literal

from pydantic import Field, model_validator

from calibctl.artifacts.common import Document, Sha256Hex, UtcDatetime

BOARD_SCHEMA_VERSION: Literal[1] = 1
BOARD_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"
_REF = re.compile(r"^(?P<name>[A-Za-z0-9][A-Za-z0-9._-]{0,63})(?:@(?P<rev>[0-9]+))?$")


class SpanMeasurement(Document):
    """A second, independent measurement of the printed pattern: the distance between the outermost inner
    corners along the long side (``squares`` squares), with its own instrument (seed chapter 0: only a
    second measurement of a distance catches a gauge error)."""

    span_m: float = Field(
        gt=0, lt=10.0, description="outermost inner corner to outermost inner corner, metres"
    )
    squares: int = Field(ge=1, description="squares the span covers (inner corners along the long side - 1)")
    uncertainty_m: float = Field(gt=0, description="one-sigma uncertainty of span_m, metres")
    instrument: str = Field(min_length=1, description="what measured it, e.g. 'steel rule 300 mm'")
    measured_by: str = Field(min_length=1, description="who measured it")
    measured_on: dt.date = Field(description="date of the measurement")


class SquareMeasurement(Document):
    """How the square size was obtained. ``measured``: the square size and an independent span measurement
    agree; ``measured-single``: one measurement only (lint warns); ``nominal``: a typed number. Boards
    registered before the span existed read as ``measured`` without a span."""

    status: Literal["measured", "measured-single", "nominal"] = Field(
        description="measured twice (square size and span agree), measured-single, or nominal (typed)"
    )
    square_size_m: float = Field(gt=0, lt=1.0, description="edge of one printed square, metres")
    uncertainty_m: float | None = Field(
        None, gt=0, description="one-sigma uncertainty of square_size_m, metres"
    )
    instrument: str | None = Field(
        None, min_length=1, description="what measured it, e.g. 'Mitutoyo 500-196 calipers'"
    )
    measured_by: str | None = Field(None, min_length=1, description="who measured it")
    measured_on: dt.date | None = Field(None, description="date of the measurement")
    evidence_sha256: Sha256Hex | None = Field(
        None, description="sha256 of the evidence file (photo of the calipers)"
    )
    evidence_name: str | None = Field(None, description="file name of the evidence when it was registered")
    # Left out of the document while absent, so boards (and calibrations) sealed before it still verify.
    span: SpanMeasurement | None = Field(
        None,
        exclude_if=lambda span: span is None,
        description="the independent span measurement; present exactly when status is measured (new boards)",
    )

    @model_validator(mode="after")
    def _provenance_complete(self) -> SquareMeasurement:
        if self.span is not None and self.status != "measured":
            raise ValueError(f"a {self.status} square size carries no span measurement")
        if self.status in ("measured", "measured-single"):
            missing = [
                name
                for name in ("uncertainty_m", "instrument", "measured_by", "measured_on")
                if getattr(self, name) is None
            ]
            if missing:
                raise ValueError(f"a measured square size needs {', '.join(missing)}")
        return self


class BackingBoard(Document):
    """The rigid board the pattern is mounted on, for targets another sensor sees by its outline (LiDAR)."""

    width_m: float = Field(
        gt=0, lt=10.0, description="backing board edge along the pattern's x (the cols direction), metres"
    )
    height_m: float = Field(
        gt=0, lt=10.0, description="backing board edge along the pattern's y (the rows direction), metres"
    )
    pattern_offset_m: tuple[float, float] = Field(
        (0.0, 0.0),
        description="pattern centre minus backing board centre along the pattern's x and y, metres",
    )


class BoardRevision(Document):
    """One immutable revision of a registered calibration board."""

    schema_version: Literal[1] = Field(BOARD_SCHEMA_VERSION, description="version of this document's schema")
    name: str = Field(pattern=BOARD_NAME_PATTERN, description="board name, unique in a store")
    revision: int = Field(ge=1, description="1, 2, ...; a re-measured board gets the next revision")
    kind: Literal["chessboard", "charuco", "aprilgrid"] = Field(description="pattern type")
    cols: int = Field(
        ge=2,
        le=200,
        description="inner corners per row (OpenCV patternSize width); AprilGrid: tag corners, 2 per tag",
    )
    rows: int = Field(
        ge=2,
        le=200,
        description="inner corners per column (OpenCV patternSize height); AprilGrid: 2 per tag",
    )
    marker_size_m: float | None = Field(None, gt=0, description="ChArUco only: marker edge, metres")
    dictionary: str | None = Field(
        None,
        description="ChArUco and AprilGrid: cv2.aruco dictionary name, e.g. DICT_5X5_100 or "
        "DICT_APRILTAG_36h11",
    )
    # Left out of the document while absent, so boards sealed before AprilGrids still verify.
    tag_spacing: float | None = Field(
        None,
        gt=0,
        le=1,
        exclude_if=lambda spacing: spacing is None,
        description="AprilGrid only: gap between tags over the tag edge (Kalibr's tagSpacing); the tag "
        "edge is the measured square size",
    )
    # ChArUco variants; left out of the document while False, so boards sealed before them still verify.
    inverted: bool = Field(
        False,
        exclude_if=lambda inverted: not inverted,
        description="ChArUco only: white markers on black squares (detected with detectInvertedMarker)",
    )
    legacy_pattern: bool = Field(
        False,
        exclude_if=lambda legacy: not legacy,
        description="ChArUco only: the layout of OpenCV < 4.6 (CharucoBoard.setLegacyPattern), for an even "
        "number of square rows",
    )
    measurement: SquareMeasurement = Field(description="the square size and where it came from")
    created_at: UtcDatetime = Field(description="when this revision was registered (UTC)")
    created_by: str = Field(min_length=1, description="who registered it")
    note: str | None = Field(None, description="free text, e.g. why it was re-measured")
    # Left out of the document while absent, so boards sealed before it still verify.
    backing: BackingBoard | None = Field(
        None,
        exclude_if=lambda backing: backing is None,
        description="the backing board's size and the pattern's place on it (camera-LiDAR targets)",
    )

    @model_validator(mode="after")
    def _charuco_fields(self) -> BoardRevision:
        if self.kind == "aprilgrid":
            if self.tag_spacing is None or self.dictionary is None or self.cols % 2 or self.rows % 2:
                raise ValueError("an AprilGrid needs tag_spacing, dictionary and two corners per tag and row")
            if self.marker_size_m is not None or self.inverted or self.legacy_pattern:
                raise ValueError("marker_size_m, inverted and legacy_pattern apply to ChArUco boards only")
            return self
        if self.tag_spacing is not None:
            raise ValueError("tag_spacing applies to AprilGrids only")
        if self.kind == "charuco":
            if self.marker_size_m is None or self.dictionary is None:
                raise ValueError("a ChArUco board needs marker_size_m and dictionary")
            if self.marker_size_m >= self.measurement.square_size_m:
                raise ValueError("the marker must be smaller than the square")
        elif (
            self.marker_size_m is not None
            or self.dictionary is not None
            or self.inverted
            or self.legacy_pattern
        ):
            raise ValueError(
                "marker_size_m, dictionary, inverted and legacy_pattern apply to ChArUco boards only"
            )
        return self

    @property
    def ref(self) -> str:
        """``NAME@REV``, how artifacts reference a board."""
        return f"{self.name}@{self.revision}"

    @property
    def square_size_m(self) -> float:
        return self.measurement.square_size_m


def parse_board_ref(ref: str) -> tuple[str, int | None]:
    """``NAME`` or ``NAME@REV`` -> (name, revision or None for the latest)."""
    match = _REF.match(ref.strip())
    if not match:
        raise ValueError(f"'{ref}' is not a board reference; expected NAME or NAME@REV (e.g. A17@2)")
    rev = match.group("rev")
    return match.group("name"), int(rev) if rev is not None else None
