"""Could the printed chessboard extend beyond the detected pattern? A cheap look past its edges.

A chessboard's inner corners are surrounded by exactly one ring of squares. So, on each side of a
detected ``cols x rows`` corner grid, the squares 0.5 squares beyond the outermost corner line (the
ring) alternate black / white, and 1.5 squares beyond it there is the board's margin or the
background. When the detector has locked onto an inner part of a larger board, the row at 1.5
squares on at least one side is another row of alternating squares.

``might_extend`` fits the board-plane -> image homography per side from the three corner lines
nearest that side (lens distortion bends a whole-board homography by a fraction of a square at the
edges) and samples the mean intensity (3 x 3 bilinear points) of each ring square 0.15-0.45 squares
past the outermost corner line (inside even the half-width outer squares of the opencv-left-right
board) and of each square of the row past it, 1.15-1.45 squares out (just past a full ring, which
ends at 1.0). Each row is correlated with the +1/-1 parity of a chessboard continued past the edge
and divided by the same correlation over the interior squares. A side says "maybe" when

- fewer than ``MIN_SQUARES`` of its ring or outer-row squares are inside the image (unknown), or
- its ring alternates with less than ``RING_MIN_FRAC`` of the interior contrast (sampling is off), or
- its outer row alternates with at least ``OUTER_MAX_FRAC`` of the interior contrast (either phase).

The measured separation (tests/core/capture/test_board_extent.py) and how pattern_check uses it are in
calibctl/workflows/camera/pattern_check.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

OUTER_MAX_FRAC = 0.2  # outer-row alternation / interior alternation from which a side is "maybe"
RING_MIN_FRAC = 0.25  # ring alternation / interior alternation below which a side is "maybe"
MIN_SQUARES = 4  # a row with fewer of its squares inside the image is "unknown" ("maybe")
RING_AT_SQ = 0.3  # ring samples centred this far past the outermost corner line (squares)...
OUTER_AT_SQ = 1.3  # ...and the outer row's (just past a full ring, which ends at 1.0)
ACROSS_HALF_SPAN_SQ = 0.15  # sampling half-span across the side, squares
ALONG_HALF_SPAN_SQ = 0.25  # and along it
INTERIOR_HALF_SPAN_SQ = 0.25
FIT_LINES = 3  # corner lines nearest a side used for its homography
# findChessboardCornersSB grows a board from this seed grid when allowed to (CALIB_CB_LARGER) and returns
# every corner it reaches: the whole visible board, whatever size was registered.
SEED_PATTERN = (3, 3)

SIDES = ("top", "bottom", "left", "right")


@dataclass(frozen=True)
class SideScore:
    """One side of the detected grid.

    Attributes:
        side: "top" (row 0), "bottom", "left" (column 0) or "right".
        ring: alternation of the ring squares / of the interior squares (about 1 on a clean board),
            None when a sample leaves the image.
        outer: alternation of the row beyond the ring / of the ring squares (about 0 on a board's
            margin, about 1 on another row of squares), None when unknown.
        maybe: True when the board might continue past this side.
    """

    side: str
    ring: float | None
    outer: float | None
    maybe: bool


def _sample_means(
    gray: np.ndarray, H_img_board: np.ndarray, centres_sq: np.ndarray, half_span_sq: tuple[float, float]
) -> np.ndarray:
    """Mean intensity of 3 x 3 points around each (M, 2) centre (board squares; +/- half_span_sq = (x, y))
    -> (M,) float64, NaN where a point falls outside the image."""
    dx, dy = np.meshgrid(
        np.linspace(-half_span_sq[0], half_span_sq[0], 3), np.linspace(-half_span_sq[1], half_span_sq[1], 3)
    )
    pts = (centres_sq[:, None, :] + np.column_stack([dx.ravel(), dy.ravel()])[None]).reshape(-1, 1, 2)
    img = cv2.perspectiveTransform(pts.astype(np.float64), H_img_board).reshape(len(centres_sq), -1, 2)
    height, width = gray.shape[:2]
    inside = (
        np.all(np.isfinite(img), axis=2)
        & (img[..., 0] >= 0)
        & (img[..., 1] >= 0)
        & (img[..., 0] <= width - 1)
        & (img[..., 1] <= height - 1)
    )
    safe = np.where(np.isfinite(img), img, -1.0).astype(np.float32)
    values = cv2.remap(gray, safe[..., 0], safe[..., 1], cv2.INTER_LINEAR).astype(np.float64)
    return np.where(inside.all(axis=1), values.mean(axis=1), np.nan)


def _alternation(values: np.ndarray, centres_sq: np.ndarray) -> float | None:
    """|correlation with the chessboard parity| over the samples inside the image: mean of
    (v - mean) * (+1/-1), intensity units; None when fewer than ``MIN_SQUARES`` are inside."""
    keep = np.isfinite(values)
    if keep.sum() < MIN_SQUARES:
        return None
    v, c = values[keep], centres_sq[keep]
    parity = np.where((np.floor(c[:, 0]) + np.floor(c[:, 1])) % 2 == 0, 1.0, -1.0)
    return float(abs(np.mean((v - v.mean()) * parity)))


def _side_row(side: str, cols: int, rows: int, beyond_sq: float) -> tuple[np.ndarray, tuple[float, float]]:
    """(M, 2) centres (x, y in squares; corner (i, j) at (j, i)) of the squares ``beyond_sq`` past a side,
    one per ring square (cols + 1 or rows + 1), and the sampling half-spans (x, y) in squares."""
    along_x, along_y = np.arange(-0.5, cols, 1.0), np.arange(-0.5, rows, 1.0)
    if side in ("top", "bottom"):
        y = -beyond_sq if side == "top" else rows - 1 + beyond_sq
        return np.column_stack([along_x, np.full_like(along_x, y)]), (ALONG_HALF_SPAN_SQ, ACROSS_HALF_SPAN_SQ)
    x = -beyond_sq if side == "left" else cols - 1 + beyond_sq
    return np.column_stack([np.full_like(along_y, x), along_y]), (ACROSS_HALF_SPAN_SQ, ALONG_HALF_SPAN_SQ)


def _fit(model_sq: np.ndarray, corners_px: np.ndarray) -> np.ndarray | None:
    H, _ = cv2.findHomography(model_sq, corners_px, 0)
    return H


def score_sides(gray: np.ndarray, corners_px: np.ndarray, cols: int, rows: int) -> list[SideScore]:
    """Score the four sides of a full detected chessboard grid.

    Args:
        gray: (H, W) uint8 image the corners were found in.
        corners_px: (cols * rows, 2) float64 corners, row-major (rows of ``cols``), full-resolution pixels.
    """
    corners_px = np.asarray(corners_px, np.float64).reshape(-1, 2)
    jj, ii = np.meshgrid(np.arange(cols), np.arange(rows))
    j, i = jj.ravel(), ii.ravel()
    model_sq = np.column_stack([j, i]).astype(np.float64)
    interior_sq = model_sq[(j < cols - 1) & (i < rows - 1)] + 0.5
    H_all = _fit(model_sq, corners_px)
    interior = (
        None
        if H_all is None
        else _alternation(
            _sample_means(gray, H_all, interior_sq, (INTERIOR_HALF_SPAN_SQ, INTERIOR_HALF_SPAN_SQ)),
            interior_sq,
        )
    )
    near = {
        "top": i < FIT_LINES,
        "bottom": i >= rows - FIT_LINES,
        "left": j < FIT_LINES,
        "right": j >= cols - FIT_LINES,
    }
    scores = []
    for side in SIDES:
        H = (
            _fit(model_sq[near[side]], corners_px[near[side]])
            if near[side].sum() >= 4 and not near[side].all()
            else H_all
        )
        ring = outer = None
        if H is not None and interior:
            ring_sq, ring_span = _side_row(side, cols, rows, RING_AT_SQ)
            outer_sq, outer_span = _side_row(side, cols, rows, OUTER_AT_SQ)
            ring = _alternation(_sample_means(gray, H, ring_sq, ring_span), ring_sq)
            outer = _alternation(_sample_means(gray, H, outer_sq, outer_span), outer_sq)
        if ring is None or outer is None or not interior:
            scores.append(SideScore(side, None, None, True))
            continue
        ring_frac, outer_frac = ring / interior, outer / interior
        scores.append(
            SideScore(side, ring_frac, outer_frac, ring_frac < RING_MIN_FRAC or outer_frac >= OUTER_MAX_FRAC)
        )
    return scores


def might_extend(gray: np.ndarray, corners_px: np.ndarray, cols: int, rows: int) -> bool:
    """True ("maybe") when the printed board might reach beyond the detected cols x rows corners on
    some side; False only when every side shows a clean ring and no alternating row past it.

    Args:
        gray: (H, W) uint8 image.
        corners_px: (cols * rows, 2) float64 corners, row-major, full-resolution pixels.
    """
    return any(score.maybe for score in score_sides(gray, corners_px, cols, rows))


def visible_chessboard(gray: np.ndarray) -> tuple[int, int] | None:
    """(a, b) inner corners of the chessboard ``findChessboardCornersSB`` sees in ``gray`` when it may grow
    from a 3x3 seed (``CALIB_CB_LARGER``), in no particular orientation (a 9x6 board may read 6x9); None
    when it sees none. Usually the whole board; a partly hidden or shaded one can read smaller, and SB can
    reach one line into a board's outer edge, so a caller confirms a size with the classic detector.

    Args:
        gray: (H, W) uint8 image at full resolution.
    """
    found, _corners, meta = cv2.findChessboardCornersSBWithMeta(gray, SEED_PATTERN, cv2.CALIB_CB_LARGER)
    if not found or meta is None or meta.ndim != 2:
        return None
    return int(meta.shape[1]), int(meta.shape[0])
