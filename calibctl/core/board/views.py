"""The unit of calibration data: one board view, as corners matched to model points."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BoardView:
    """One detected board in one image.

    Attributes:
        name: the image it came from (file name or ``frame-000123``), for reports.
        corner_ids: (N,) int64 ids into the board's model points (row-major, see board_geometry).
        corners_px: (N, 2) float64 sub-pixel corner positions, pixel centres at integer coordinates
            (OpenCV convention: the top-left pixel's centre is (0, 0)).
    """

    name: str
    corner_ids: np.ndarray
    corners_px: np.ndarray

    def __post_init__(self) -> None:
        ids = np.asarray(self.corner_ids, dtype=np.int64).reshape(-1)
        px = np.asarray(self.corners_px, dtype=np.float64).reshape(-1, 2)
        if ids.shape[0] != px.shape[0]:
            raise ValueError(f"view {self.name}: {ids.shape[0]} ids but {px.shape[0]} corners")
        object.__setattr__(self, "corner_ids", ids)
        object.__setattr__(self, "corners_px", px)

    def object_points(self, model_points_m: np.ndarray) -> np.ndarray:
        """(N, 3) float64 model points (board frame, metres) matching ``corners_px``."""
        return np.asarray(model_points_m, dtype=np.float64)[self.corner_ids]
