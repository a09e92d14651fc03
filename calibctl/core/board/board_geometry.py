"""Board model points in the board frame.

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
