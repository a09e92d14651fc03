"""What the detector and the renderer need to know about a printed calibration target.

A ``BoardSpec`` is the core-layer view of a board: geometry only, no names or revisions (those live in
the artifact layer). Both kinds are described by their *inner-corner* grid, ``cols`` x ``rows`` (OpenCV
``patternSize=(cols, rows)``), so a ChArUco board of ``squares_x`` x ``squares_y`` squares has
``cols = squares_x - 1`` and ``rows = squares_y - 1``. Corner ids are row-major
(``id = row * cols + col``), the order of ``board_geometry.chessboard_object_points``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from calibctl.core.board.board_geometry import chessboard_object_points

if TYPE_CHECKING:
    import cv2

CHESSBOARD = "chessboard"
CHARUCO = "charuco"
BOARD_KINDS = (CHESSBOARD, CHARUCO)


@dataclass(frozen=True)
class BoardSpec:
    """A planar target.

    Attributes:
        kind: "chessboard" or "charuco".
        cols, rows: inner corners per row / per column.
        square_size_m: edge of one printed square, metres.
        marker_size_m: ChArUco marker edge, metres (ChArUco only).
        dictionary: ChArUco dictionary name as in cv2.aruco, e.g. "DICT_4X4_50" (ChArUco only).
        legacy_pattern: ChArUco boards printed by OpenCV < 4.6 with an even number of rows
            (cv2.aruco.CharucoBoard.setLegacyPattern).
        inverted: ChArUco printed white markers on black squares (caliscope's boards); the detector then
            also reads inverted markers (``DetectorParameters.detectInvertedMarker``).
    """

    kind: str
    cols: int
    rows: int
    square_size_m: float
    marker_size_m: float | None = None
    dictionary: str | None = None
    legacy_pattern: bool = False
    inverted: bool = False

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

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    @property
    def squares(self) -> tuple[int, int]:
        """(squares_x, squares_y) printed squares."""
        return self.cols + 1, self.rows + 1

    def object_points(self) -> np.ndarray:
        """(cols * rows, 3) float64 model points, metres, board frame, row-major, z = 0."""
        return chessboard_object_points(self.cols, self.rows, self.square_size_m)

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
