"""What the detector and the renderer need to know about a printed calibration target.

A ``BoardSpec`` is the core-layer view of a board: geometry only, no names or revisions (those live in
the artifact layer). Both kinds are described by their *inner-corner* grid, ``cols`` x ``rows`` (OpenCV
``patternSize=(cols, rows)``), so a ChArUco board of ``squares_x`` x ``squares_y`` squares has
``cols = squares_x - 1`` and ``rows = squares_y - 1``. Corner ids are row-major
(``id = row * cols + col``), the order of ``board_geometry.chessboard_object_points``.

An AprilGrid (Kalibr's target) is described by its grid of tag corners: ``tag_cols`` x ``tag_rows`` tags
give ``cols = 2 * tag_cols`` and ``rows = 2 * tag_rows`` points, four per tag, numbered as Kalibr numbers
them (``GridCalibrationTargetAprilgrid``): row-major from tag 0's bottom-left corner, ``x`` along the tag
columns, ``y`` up the printed target (tag ``n`` sits at column ``n % tag_cols``, row ``n // tag_cols``), so
the board frame is Kalibr's own (its ``z`` points out of the printed face). ``square_size_m`` is the tag
edge (the outer edge of its black border) and ``tag_spacing`` the gap between tags as a fraction of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from calibctl.core.board.board_geometry import aprilgrid_object_points, chessboard_object_points

if TYPE_CHECKING:
    import cv2

CHESSBOARD = "chessboard"
CHARUCO = "charuco"
APRILGRID = "aprilgrid"
BOARD_KINDS = (CHESSBOARD, CHARUCO, APRILGRID)
APRILTAG_FAMILIES = {
    "36h11": "DICT_APRILTAG_36h11",
    "36h10": "DICT_APRILTAG_36h10",
    "25h9": "DICT_APRILTAG_25h9",
    "16h5": "DICT_APRILTAG_16h5",
}
"""AprilTag families OpenCV's aruco module decodes, by the name Kalibr and the AprilTag library use."""
APRILGRID_BORDER_BITS = 2
"""Kalibr prints each tag with a black border two bits wide (kalibr_create_target_pdf, ``borderBits=2``)."""


@dataclass(frozen=True)
class BoardSpec:
    """A planar target.

    Attributes:
        kind: "chessboard", "charuco" or "aprilgrid".
        cols, rows: inner corners per row / per column (AprilGrid: tag corners, two per tag).
        square_size_m: edge of one printed square, metres (AprilGrid: the tag edge).
        marker_size_m: ChArUco marker edge, metres (ChArUco only).
        dictionary: marker dictionary name as in cv2.aruco, e.g. "DICT_4X4_50" (ChArUco) or
            "DICT_APRILTAG_36h11" (AprilGrid).
        legacy_pattern: ChArUco boards printed by OpenCV < 4.6 with an even number of rows
            (cv2.aruco.CharucoBoard.setLegacyPattern).
        inverted: ChArUco printed white markers on black squares (caliscope's boards); the detector then
            also reads inverted markers (``DetectorParameters.detectInvertedMarker``).
        tag_spacing: AprilGrid only: the gap between neighbouring tags over the tag edge (Kalibr's
            ``tagSpacing``), in (0, 1].
    """

    kind: str
    cols: int
    rows: int
    square_size_m: float
    marker_size_m: float | None = None
    dictionary: str | None = None
    legacy_pattern: bool = False
    inverted: bool = False
    tag_spacing: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in BOARD_KINDS:
            raise ValueError(f"unknown board kind {self.kind!r}; expected one of {', '.join(BOARD_KINDS)}")
        if self.cols < 2 or self.rows < 2:
            raise ValueError(f"a board needs at least 2x2 inner corners, got {self.cols}x{self.rows}")
        if not self.square_size_m > 0:
            raise ValueError(f"square size must be positive, got {self.square_size_m}")
        if self.kind == CHARUCO:
            if self.marker_size_m is None or not 0 < self.marker_size_m < self.square_size_m:
                raise ValueError("a ChArUco board needs 0 < marker_size_m < square_size_m")
            import cv2  # here, not at the top: `board list` and other read commands never need it

            if self.dictionary is None or not hasattr(cv2.aruco, self.dictionary):
                raise ValueError(f"unknown ArUco dictionary {self.dictionary!r}")
        elif self.legacy_pattern or self.inverted:
            raise ValueError("the legacy layout and inverted markers apply to ChArUco boards only")
        if self.kind == APRILGRID:
            self._check_aprilgrid()
        elif self.tag_spacing is not None:
            raise ValueError("the tag spacing applies to AprilGrids only")

    def _check_aprilgrid(self) -> None:
        if self.cols % 2 or self.rows % 2:
            raise ValueError(f"an AprilGrid has two corners per tag and row, got {self.cols}x{self.rows}")
        if self.tag_spacing is None or not 0 < self.tag_spacing <= 1:
            raise ValueError(f"the tag spacing must be in (0, 1] of the tag edge, got {self.tag_spacing}")
        if self.marker_size_m is not None:
            raise ValueError("an AprilGrid's marker is its tag: give the tag edge as the square size")
        if self.dictionary not in APRILTAG_FAMILIES.values():
            raise ValueError(
                f"unknown AprilTag dictionary {self.dictionary!r}; OpenCV decodes the families "
                f"{', '.join(APRILTAG_FAMILIES)}"
            )

    @classmethod
    def chessboard(cls, cols: int, rows: int, square_size_m: float) -> BoardSpec:
        return cls(CHESSBOARD, cols, rows, square_size_m)

    @classmethod
    def charuco(
        cls,
        squares_x: int,
        squares_y: int,
        square_size_m: float,
        marker_size_m: float,
        dictionary: str = "DICT_4X4_50",
        *,
        legacy_pattern: bool = False,
        inverted: bool = False,
    ) -> BoardSpec:
        return cls(
            CHARUCO,
            squares_x - 1,
            squares_y - 1,
            square_size_m,
            marker_size_m,
            dictionary,
            legacy_pattern,
            inverted,
        )

    @classmethod
    def aprilgrid(
        cls, tag_cols: int, tag_rows: int, tag_size_m: float, tag_spacing: float, family: str = "36h11"
    ) -> BoardSpec:
        """Kalibr's target.yaml: ``tagCols``, ``tagRows``, ``tagSize`` (metres), ``tagSpacing`` (ratio)."""
        if family not in APRILTAG_FAMILIES:
            raise ValueError(
                f"OpenCV has no AprilTag family {family!r}; choose one of {', '.join(APRILTAG_FAMILIES)}"
            )
        return cls(
            APRILGRID,
            2 * tag_cols,
            2 * tag_rows,
            tag_size_m,
            dictionary=APRILTAG_FAMILIES[family],
            tag_spacing=tag_spacing,
        )

    @property
    def tags(self) -> tuple[int, int]:
        """(tag_cols, tag_rows) of an AprilGrid."""
        return self.cols // 2, self.rows // 2

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    @property
    def squares(self) -> tuple[int, int]:
        """(squares_x, squares_y) printed squares."""
        return self.cols + 1, self.rows + 1

    def object_points(self) -> np.ndarray:
        """(cols * rows, 3) float64 model points, metres, board frame, row-major, z = 0."""
        if self.kind == APRILGRID:
            assert self.tag_spacing is not None  # checked in __post_init__
            return aprilgrid_object_points(self.cols, self.rows, self.square_size_m, self.tag_spacing)
        return chessboard_object_points(self.cols, self.rows, self.square_size_m)

    def printed_bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((x, y) low, (x, y) high) of the printed pattern, quiet zone excluded, in square (tag) units."""
        if self.kind == APRILGRID:
            assert self.tag_spacing is not None
            pitch = 1.0 + self.tag_spacing
            tag_cols, tag_rows = self.tags
            return (-self.tag_spacing, -self.tag_spacing), (tag_cols * pitch, tag_rows * pitch)
        return (-1.0, -1.0), (float(self.cols), float(self.rows))

    def centre_m(self) -> np.ndarray:
        """(3,) the middle of the corner grid, board frame, metres."""
        if self.kind == APRILGRID:
            return self.object_points().mean(axis=0)
        return np.array([(self.cols - 1) / 2, (self.rows - 1) / 2, 0.0]) * self.square_size_m

    def to_dict(self) -> dict[str, object]:
        return {
            "kind": self.kind,
            "cols": self.cols,
            "rows": self.rows,
            "square_size_m": self.square_size_m,
            "marker_size_m": self.marker_size_m,
            "dictionary": self.dictionary,
            "legacy_pattern": self.legacy_pattern,
            "inverted": self.inverted,
            **({"tag_spacing": self.tag_spacing} if self.tag_spacing is not None else {}),
        }


def make_charuco_board(spec: BoardSpec) -> cv2.aruco.CharucoBoard:
    """The OpenCV board object for a ChArUco spec (its own frame origin is the outer top-left corner)."""
    import cv2

    if spec.kind != CHARUCO:
        raise ValueError(f"not a ChArUco board: {spec.kind}")
    assert spec.marker_size_m is not None  # checked in __post_init__
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, str(spec.dictionary)))
    board = cv2.aruco.CharucoBoard(spec.squares, spec.square_size_m, spec.marker_size_m, dictionary)
    board.setLegacyPattern(spec.legacy_pattern)
    return board
