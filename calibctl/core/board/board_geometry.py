"""Board model points in the board frame (chessboard and ChArUco below; AprilGrid: see its function).

Conventions (see docs/conventions.md): the board frame has its origin at the first inner corner,
x along the columns, y along the rows, z out of the printed face, so every model point has
z = 0 exactly. Units are metres. Corner ids are row-major (id = row * cols + col), which is the
order cv2.findChessboardCorners returns for a board that is not flipped, and the order of
cv2.aruco.CharucoBoard.getChessboardCorners().
"""

from __future__ import annotations

import numpy as np


def chessboard_object_points(cols: int, rows: int, square_size_m: float) -> np.ndarray:
    """Inner-corner model points of a chessboard.

    Args:
        cols, rows: inner corners per row and per column (OpenCV ``patternSize=(cols, rows)``).
        square_size_m: edge of one printed square, metres.

    Returns:
        (cols * rows, 3) float64, row-major, z = 0.
    """
    if cols < 2 or rows < 2:
        raise ValueError(f"a chessboard needs at least 2x2 inner corners, got {cols}x{rows}")
    if not square_size_m > 0:
        raise ValueError(f"square size must be positive, got {square_size_m}")
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2).astype(np.float64)
    points = np.zeros((cols * rows, 3), dtype=np.float64)
    points[:, :2] = grid * square_size_m
    return points


def charuco_object_points(squares_x: int, squares_y: int, square_size_m: float) -> np.ndarray:
    """Inner-corner model points of a ChArUco board of ``squares_x`` x ``squares_y`` squares.

    A ChArUco board has (squares_x - 1) x (squares_y - 1) inner corners, laid out like a chessboard's.

    Returns:
        ((squares_x - 1) * (squares_y - 1), 3) float64, row-major, z = 0.
    """
    return chessboard_object_points(squares_x - 1, squares_y - 1, square_size_m)


def aprilgrid_object_points(cols: int, rows: int, tag_size_m: float, tag_spacing: float) -> np.ndarray:
    """Tag-corner model points of a Kalibr AprilGrid of ``cols // 2`` x ``rows // 2`` tags.

    Kalibr's layout (``GridCalibrationTargetAprilgrid::createGridPoints``): point ``r * cols + c`` lies at
    ``x = (c // 2) * (1 + tag_spacing) * tag_size + (c % 2) * tag_size`` and likewise ``y`` with ``r``,
    so tag ``n`` (column ``n % (cols // 2)``, row ``n // (cols // 2)``) owns points ``b``, ``b + 1``,
    ``b + cols + 1`` and ``b + cols`` (bottom-left, bottom-right, top-right, top-left) with
    ``b = (n // (cols // 2)) * 2 * cols + (n % (cols // 2)) * 2``.

    Returns:
        (cols * rows, 3) float64, row-major, z = 0.
    """
    c = np.arange(cols)
    r = np.arange(rows)
    x = ((c // 2) * (1.0 + tag_spacing) + (c % 2)) * tag_size_m
    y = ((r // 2) * (1.0 + tag_spacing) + (r % 2)) * tag_size_m
    points = np.zeros((rows * cols, 3), dtype=np.float64)
    points[:, 0] = np.tile(x, rows)
    points[:, 1] = np.repeat(y, cols)
    return points


def aprilgrid_tag_point_ids(tag_ids: np.ndarray, cols: int) -> np.ndarray:
    """(N, 4) point ids of tags ``tag_ids``: bottom-left, bottom-right, top-right, top-left (Kalibr's
    ``pIdx``) on a grid of ``cols`` points per row."""
    tags = np.asarray(tag_ids, dtype=np.int64).reshape(-1)
    base = (tags // (cols // 2)) * 2 * cols + (tags % (cols // 2)) * 2
    return np.stack([base, base + 1, base + cols + 1, base + cols], axis=1)
