"""The image circle of a circular fisheye: found in a session's frames, or given, and the cells it covers.

A circular fisheye images a disc; outside it the sensor stays black in every frame. The session's
frames are reduced to one picture, their per-pixel maximum (``accumulate_max``): whatever the lens
ever imaged is lit in it. ``detect_image_circle`` then decides whether there is a circle at all and
where it is:

  * lit = brighter than ``max(DARK_FLOOR, DARK_FRACTION * p90)``, p90 the 90th percentile of the
    maximum picture (the level a well-lit pixel reaches);
  * all four corner patches of the frame must be dark (a pinhole or full-frame fisheye images its
    corners: no circle, and the gates behave exactly as without one);
  * the boundary of the largest lit region, minus the points on the frame's edge (a circle taller
    than the frame is cut there) and minus the points inside its convex hull (dark things inside the
    circle that reach its rim: the lens housing, a dark scene), is fitted with a circle by least
    squares (Kasa's algebraic fit), which must explain it to within
    ``max(FIT_TOLERANCE_PX, FIT_TOLERANCE_FRAC * r)`` (median) and leave nothing lit outside it
    (``LIT_OUTSIDE_MAX``): a dark vignette or a dark scene is not a circle.

Coverage (core.capture.gates) is then counted over the cells of its grid that lie mostly inside the circle
(``cells_inside``), so the black corners of a circular fisheye are not asked for.
Pixel coordinates: origin at the centre of the top-left pixel, x right, y down (docs/conventions.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

DARK_FLOOR = 16.0  # grey levels: a pixel of the maximum picture at or below this was never lit
DARK_FRACTION = 0.25  # ... nor one under this fraction of a well-lit pixel's level (p90)
CORNER_PATCH_FRAC = 0.04  # the corner patches that must be dark: this fraction of the short side
FIT_TOLERANCE_PX = 1.5  # median |distance - r| of the boundary points (in the picture's own pixels)
FIT_TOLERANCE_FRAC = 0.01  # ... or this fraction of r, whichever is larger
LIT_OUTSIDE_MAX = 0.01  # fraction of the frame that may be lit outside the fitted circle
MIN_BOUNDARY_POINTS = 32
HULL_TOLERANCE_PX = 1.5  # boundary points this far inside the lit region's convex hull still count as its rim
CELL_SAMPLES = 24  # samples per cell side to measure the part of a cell inside the circle
CELL_INSIDE_MIN = 0.5  # a cell counts when more than half of it is inside the circle


@dataclass(frozen=True)
class ImageCircle:
    """The disc the lens images, in pixels of the full frame. ``source``: "detected" or "given"."""

    cx_px: float
    cy_px: float
    radius_px: float
    source: str

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.cx_px, self.cy_px, self.radius_px)

    def describe(self) -> str:
        how = "detected from the frames" if self.source == "detected" else "given"
        return (
            f"image circle centre ({self.cx_px:.1f}, {self.cy_px:.1f}) px, radius {self.radius_px:.1f} "
            f"px ({how})"
        )


def half_size(gray: np.ndarray) -> np.ndarray:
    """``gray`` (H, W) at half size, area-averaged: enough to find an image circle, a quarter of the pixels
    to keep per session. Every capture path reduces its frames this way before ``accumulate_max``."""
    import cv2  # here, as in detect_image_circle: read commands load no OpenCV

    height, width = gray.shape[:2]
    return cv2.resize(gray, (max(1, width // 2), max(1, height // 2)), interpolation=cv2.INTER_AREA)


def sized_half(gray: np.ndarray) -> tuple[tuple[int, int], np.ndarray]:
    """((W, H) of ``gray``, ``half_size(gray)``): what a detection worker hands back for the frames'
    maximum."""
    return (int(gray.shape[1]), int(gray.shape[0])), half_size(gray)


def accumulate_max(acc: np.ndarray | None, gray: np.ndarray) -> np.ndarray:
    """The per-pixel maximum of ``acc`` and ``gray`` ((H, W) uint8); ``gray`` itself when acc is None or
    of another shape (the first frame of a session)."""
    gray = np.asarray(gray)
    if acc is None or acc.shape != gray.shape:
        return gray.copy()
    return np.maximum(acc, gray, out=acc)


def detect_image_circle(max_gray: np.ndarray, image_size: tuple[int, int]) -> ImageCircle | None:
    """The image circle in a session's maximum picture (see the module docstring), or None.

    Args:
        max_gray: (h, w) uint8, the per-pixel maximum of the frames, at the frames' size or reduced
            by any factor (the circle is scaled back to ``image_size``).
        image_size: (W, H) of the frames, pixels.
    """
    picture = np.asarray(max_gray)
    if picture.ndim != 2 or min(picture.shape) < 16:
        return None
    h, w = picture.shape
    p90 = float(np.percentile(picture, 90))
    threshold = max(DARK_FLOOR, DARK_FRACTION * p90)
    if p90 <= threshold:
        return None  # nothing is well lit: no way to tell a circle from a dark scene
    lit = picture > threshold
    patch = max(2, int(round(CORNER_PATCH_FRAC * min(h, w))))
    if any(
        lit[rows, cols].any()
        for rows in (slice(0, patch), slice(h - patch, h))
        for cols in (slice(0, patch), slice(w - patch, w))
    ):
        return None
    fitted = _fit_boundary(lit)
    if fitted is None:
        return None
    cx, cy, r = fitted
    v, u = np.mgrid[0:h, 0:w]
    outside = np.hypot(u - cx, v - cy) > r + max(FIT_TOLERANCE_PX, FIT_TOLERANCE_FRAC * r)
    if np.count_nonzero(lit & outside) > LIT_OUTSIDE_MAX * lit.size:
        return None
    sx, sy = image_size[0] / w, image_size[1] / h
    # a reduced pixel i spans full pixels [i*s, (i+1)*s): its centre is at (i + 0.5) * s - 0.5
    return ImageCircle((cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5, r * math.sqrt(sx * sy), "detected")


def _fit_boundary(lit: np.ndarray) -> tuple[float, float, float] | None:
    """(cx, cy, r) of the circle through the lit region's boundary away from the frame's edge, or None."""
    import cv2  # here: lint reads recorded circles through this module, and read commands load no OpenCV

    mask = cv2.morphologyEx(lit.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None
    contour = max(contours, key=cv2.contourArea)
    pts = contour.reshape(-1, 2).astype(np.float64)
    h, w = lit.shape
    keep = (pts[:, 0] > 1) & (pts[:, 0] < w - 2) & (pts[:, 1] > 1) & (pts[:, 1] < h - 2)
    # Only the rim: where something dark inside the circle reaches its edge, the lit region's boundary
    # runs inside its convex hull, and those points are not on the circle. Real 960x600 circular
    # fisheye (sourishg/fisheye-stereo-calibration imgs/left*.jpg): the brown lens housing and the dark
    # floor bound the lit region at the bottom; fitted on the whole boundary (median 12.9 half-size px
    # off, limit 1.8) no circle was found and coverage asked for three black corners; on the rim alone
    # (0.33 px off) the circle is (471.9, 307.3) px, r 385 px, where the fisheye solve puts cx, cy at
    # (471.4, 305.6).
    hull = cv2.convexHull(contour)
    inside = np.array([cv2.pointPolygonTest(hull, (float(x), float(y)), True) for x, y in pts])
    keep &= inside <= HULL_TOLERANCE_PX
    pts = pts[keep]
    if len(pts) < MIN_BOUNDARY_POINTS:
        return None
    # Kasa: x^2 + y^2 + D x + E y + F = 0, linear least squares
    A = np.column_stack([pts[:, 0], pts[:, 1], np.ones(len(pts))])
    b = -(pts[:, 0] ** 2 + pts[:, 1] ** 2)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    cx, cy = -D / 2, -E / 2
    r2 = cx * cx + cy * cy - F
    if not r2 > 0:
        return None
    r = math.sqrt(r2)
    misfit = float(np.median(np.abs(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) - r)))
    if misfit > max(FIT_TOLERANCE_PX, FIT_TOLERANCE_FRAC * r):
        return None
    # the boundary pixels are the outermost lit ones: the edge lies half a pixel beyond them
    return float(cx), float(cy), r + 0.5


def circle_problem(circle: tuple[float, float, float], image_size: tuple[int, int]) -> str | None:
    """Why a given circle (cx, cy, r) px cannot be the image circle of a (W, H) frame, or None."""
    cx, cy, r = circle
    w, h = image_size
    if not all(math.isfinite(x) for x in circle):
        return f"the image circle ({cx}, {cy}, {r}) is not three finite numbers"
    if r <= 0:
        return f"the image circle's radius must be positive, got {r:g} px"
    if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
        return (
            f"the image circle's centre ({cx:g}, {cy:g}) px lies outside the {w}x{h} image "
            f"(x -0.5..{w - 0.5:g}, y -0.5..{h - 0.5:g})"
        )
    if not cells_inside(ImageCircle(cx, cy, r, "given"), image_size, 3):
        return (
            f"the image circle (centre ({cx:g}, {cy:g}) px, radius {r:g} px) covers no cell of the 3x3 "
            f"coverage grid over the {w}x{h} image by more than half"
        )
    return None


def cells_inside(circle: ImageCircle, image_size: tuple[int, int], grid: int) -> set[tuple[int, int]]:
    """(row, col) cells of a grid x grid split of the (W, H) image more than half inside the circle."""
    mask = cells_inside_mask(circle, image_size, (grid, grid))
    return {(int(r), int(c)) for r, c in zip(*np.nonzero(mask), strict=True)}


def cells_inside_mask(circle: ImageCircle, image_size: tuple[int, int], cells: tuple[int, int]) -> np.ndarray:
    """(rows, cols) bool: which cells of a cols x rows split of the (W, H) image are more than half inside
    the circle (the cells a circular fisheye images; the others it cannot)."""
    w, h = image_size
    cols, rows = cells
    t = (np.arange(CELL_SAMPLES) + 0.5) / CELL_SAMPLES
    mask = np.zeros((rows, cols), dtype=bool)
    for row in range(rows):
        for col in range(cols):
            u = (col + t) * w / cols - 0.5
            v = (row + t) * h / rows - 0.5
            uu, vv = np.meshgrid(u, v)
            inside = np.hypot(uu - circle.cx_px, vv - circle.cy_px) <= circle.radius_px
            mask[row, col] = inside.mean() > CELL_INSIDE_MIN
    return mask


def corners_inside(corners_px: np.ndarray, circle: ImageCircle) -> np.ndarray:
    """(N,) bool: which of (N, 2) pixel points lie inside the circle."""
    px = np.asarray(corners_px, np.float64).reshape(-1, 2)
    return np.hypot(px[:, 0] - circle.cx_px, px[:, 1] - circle.cy_px) <= circle.radius_px


CIRCLE_KEYS = (
    "image_circle_cx_px",
    "image_circle_cy_px",
    "image_circle_radius_px",
)  # in the coverage gate's detail


def circle_detail(circle: ImageCircle) -> dict[str, float | str]:
    """How a session records its image circle: keys of the coverage gate's ``detail``."""
    values = (round(circle.cx_px, 2), round(circle.cy_px, 2), round(circle.radius_px, 2))
    return {**dict(zip(CIRCLE_KEYS, values, strict=True)), "image_circle_source": circle.source}


def circle_from_detail(detail: Mapping[str, object]) -> ImageCircle | None:
    """The circle a coverage gate's ``detail`` records, or None (no circle, or an older session)."""
    values = [detail.get(k) for k in CIRCLE_KEYS]
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return None
    cx, cy, r = (float(v) for v in values)  # type: ignore[arg-type]
    source = detail.get("image_circle_source")
    return ImageCircle(cx, cy, r, source if isinstance(source, str) else "given")
