"""Capture gates, computed from detected corners before any solve (seed chapter 1).

Observability is sigma5/sigma1 of Zhang's stacked V matrix: two rows per view,
``v12`` and ``v11 - v22``, built from that view's board-to-image homography H.

How the coordinates are normalised (and why):
  * Board side: H is fitted from the model points in whatever unit they come in, and each view's H is
    rescaled so that ``||[h1 h2]||_F = 1`` before its rows are stacked. V only contains h1 and h2, a
    change of board units multiplies both by the same factor (seed chapter 0) and the per-view rescale
    removes it, so the gauge does not depend on the square size or its unit, nor on where the board
    origin is (that only moves h3). It also removes the arbitrary DLT scale of each view.
  * Image side: pixel coordinates are re-expressed at a reference readout whose long side is
    ``REFERENCE_LONG_SIDE_PX`` = 640 px, origin at the top-left pixel:
    ``u_n = u * 640 / max(W, H)``, ``v_n = v * 640 / max(W, H)``. Reading the same lens out at another
    resolution multiplies every pixel coordinate (and K) by a common factor, which this undoes, so the
    gauge is a property of the lens and the poses, not of the readout. At 640x480 the map is the
    identity, so the gauge equals the seed's sigma5/sigma1 of the pixel-unit V: its table (f = 800 px,
    c = (320, 240), 8 views at tilt T in evenly spread directions, board at 0.60 m) is reproduced to
    about 1% (tests/core/capture/test_gates.py). A centred, Hartley-style normalisation was tried and
    rejected:
    it is also resolution-free but changes the value by ~300x and not by a constant factor, so the
    seed's 1e-4 threshold would no longer mean what chapter 1 measured.

Tilt and tilt directions come from calibctl.core.capture.tilt: every view's pose through a small lens model
fitted to the session (f, k1, k2; principal point at the centre), so barrel distortion no longer reads
as tilt; a view with fewer than 8 corners, or whose corners span too small an area for its normal to be
known within 2 deg, is used neither for tilt nor for observability, and the report names it. Directions
count as distinct only when at least 90 deg apart (three directions are three sides of the board).
Observability is computed on those views' homographies after undistortion through the same lens.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from calibctl.core.blas_threads import single_threaded
from calibctl.core.board.views import BoardView
from calibctl.core.capture.image_circle import ImageCircle, cells_inside, circle_detail
from calibctl.core.capture.tilt import (
    DISTINCT_DIRECTION_DEG,
    MIN_TILT_CORNERS,
    SessionLens,
    directions_to_add,
    distinct_directions,
    session_tilts,
)
from calibctl.core.gate import GateResult

# Defaults (mirrors calibctl.config.GateThresholds; core may not import config).
OBSERVABILITY_MIN = 1e-4
TILT_MIN_DEG = 20.0
TILT_MAX_DEG = 45.0
TILT_DIRECTIONS_MIN = 3
MIN_VIEWS = 8
REFERENCE_LONG_SIDE_PX = 640.0
COVERAGE_GRID = 3
MAX_DISTINCT_DIRECTIONS = int(360 // DISTINCT_DIRECTION_DEG)

DIRECTION_NAMES = ("right", "bottom right", "bottom", "bottom left", "left", "top left", "top", "top right")
CELL_NAMES = (
    ("top-left corner", "top edge", "top-right corner"),
    ("left edge", "centre", "right edge"),
    ("bottom-left corner", "bottom edge", "bottom-right corner"),
)


@dataclass(frozen=True)
class GateThresholds:
    observability_min: float = OBSERVABILITY_MIN
    tilt_min_deg: float = TILT_MIN_DEG
    tilt_max_deg: float = TILT_MAX_DEG
    tilt_directions_min: int = TILT_DIRECTIONS_MIN
    min_views: int = MIN_VIEWS

    def __post_init__(self) -> None:
        # Distinct directions are >= 90 deg apart, so at most 4 fit around the circle.
        if not 1 <= self.tilt_directions_min <= MAX_DISTINCT_DIRECTIONS:
            raise ValueError(
                f"tilt_directions_min must be 1-{MAX_DISTINCT_DIRECTIONS}, got {self.tilt_directions_min}"
            )


@dataclass(frozen=True)
class ViewGeometry:
    """Per-view pose summary. ``direction_name`` is None when the board is square-on (tilt < 1 deg).

    ``tilt_sigma_deg``: one-sigma of the board normal at the assumed corner noise
    (calibctl.core.capture.tilt).
    """

    name: str
    tilt_deg: float
    direction_deg: float
    direction_name: str | None
    n_corners: int
    tilt_sigma_deg: float = 0.0


@dataclass(frozen=True)
class GateReport:
    gates: tuple[GateResult, ...]
    views: tuple[ViewGeometry, ...]
    covered_cells: tuple[str, ...]
    tilt_directions: tuple[str, ...]
    focal_px: float
    focal_source: str
    unused_views: tuple[tuple[str, str], ...] = ()  # (view name, why it gives no tilt / observability)
    lens: SessionLens | None = None  # the small lens model tilt was read through (None: no usable view)

    @property
    def passed(self) -> bool:
        return all(g.passed for g in self.gates)

    @property
    def reasons(self) -> list[str]:
        return [g.reason for g in self.gates if g.reason]

    @property
    def hints(self) -> list[str]:
        return [g.hint for g in self.gates if g.hint]

    def gate(self, name: str) -> GateResult:
        return next(g for g in self.gates if g.gate == name)


def pixel_normaliser(image_size: tuple[int, int]) -> np.ndarray:
    """(3, 3) map from pixels to the 640-px reference readout (see the module docstring)."""
    s = REFERENCE_LONG_SIDE_PX / float(max(image_size))
    return np.diag([s, s, 1.0])


def view_homography(model_xy: np.ndarray, corners_px: np.ndarray) -> np.ndarray | None:
    """(3, 3) least-squares homography board plane -> pixels, or None for < 4 or degenerate points.

    Args:
        model_xy: (N, 2) board-plane model coordinates, any unit.
        corners_px: (N, 2) pixels.
    """
    model_xy = np.asarray(model_xy, np.float64).reshape(-1, 2)
    corners_px = np.asarray(corners_px, np.float64).reshape(-1, 2)
    if model_xy.shape[0] < 4:
        return None
    H, _ = cv2.findHomography(model_xy, corners_px, 0)
    if H is None or not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-300:
        return None
    return H


def _v_row(H: np.ndarray, i: int, j: int) -> np.ndarray:
    return np.array(
        [
            H[0, i] * H[0, j],
            H[0, i] * H[1, j] + H[1, i] * H[0, j],
            H[1, i] * H[1, j],
            H[2, i] * H[0, j] + H[0, i] * H[2, j],
            H[2, i] * H[1, j] + H[1, i] * H[2, j],
            H[2, i] * H[2, j],
        ]
    )


def zhang_v(homographies: Sequence[np.ndarray], image_size: tuple[int, int]) -> np.ndarray:
    """(2n, 6) Zhang's V from n pixel homographies, normalised as the module docstring says."""
    N = pixel_normaliser(image_size)
    rows = []
    for H in homographies:
        Hn = N @ np.asarray(H, np.float64)
        Hn = Hn / np.linalg.norm(Hn[:, :2])
        rows += [_v_row(Hn, 0, 1), _v_row(Hn, 0, 0) - _v_row(Hn, 1, 1)]
    return np.array(rows).reshape(-1, 6)


def observability(homographies: Sequence[np.ndarray], image_size: tuple[int, int]) -> float:
    """sigma5 / sigma1 of V (0.0 with fewer than 3 views: V cannot reach rank 5)."""
    if len(homographies) < 3:
        return 0.0
    sv = np.linalg.svd(zhang_v(homographies, image_size), compute_uv=False)
    return float(sv[4] / sv[0]) if sv[0] > 0 else 0.0


def estimate_focal_px(homographies: Sequence[np.ndarray], image_size: tuple[int, int]) -> float | None:
    """Focal length (px) from Zhang's two constraints with c = image centre, square pixels, no skew.

    With pixels centred, B is proportional to diag(1, 1, f^2), so each constraint is linear in f^2:
    ``a + f^2 b = 0``. Returns None when the views are too flat to tell (sum of b^2 tiny) or the fit
    is not a plausible lens (f outside 0.2..5 x the image diagonal).
    """
    width, height = image_size
    C = np.array([[1.0, 0.0, -(width - 1) / 2], [0.0, 1.0, -(height - 1) / 2], [0.0, 0.0, 1.0]])
    diag = math.hypot(width, height)
    num = den = 0.0
    for H in homographies:
        Hc = C @ H
        Hc = Hc / np.linalg.norm(Hc[:2, :2])
        h1, h2 = Hc[:, 0], Hc[:, 1]
        for a, b in (
            (h1[0] * h2[0] + h1[1] * h2[1], h1[2] * h2[2]),
            (h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2, h1[2] ** 2 - h2[2] ** 2),
        ):
            num -= a * b
            den += b * b
    if den * diag**4 < 1e-6 or num <= 0:
        return None
    f = math.sqrt(num / den)
    return f if 0.2 * diag <= f <= 5 * diag else None


def view_tilt(H: np.ndarray, image_size: tuple[int, int], focal_px: float) -> tuple[float, float]:
    """(tilt_deg, direction_deg) of one view; direction is the image azimuth (y down) of the far side."""
    width, height = image_size
    K = np.array([[focal_px, 0.0, (width - 1) / 2], [0.0, focal_px, (height - 1) / 2], [0.0, 0.0, 1.0]])
    M = np.linalg.solve(K, H)
    r1 = M[:, 0] / np.linalg.norm(M[:, 0])
    r2 = M[:, 1] / np.linalg.norm(M[:, 1])
    n = np.cross(r1, r2)
    n /= np.linalg.norm(n)
    m = -n if n[2] > 0 else n  # camera-facing normal: it leans toward the far side
    tilt = math.degrees(math.acos(min(1.0, abs(n[2]))))
    direction = math.degrees(math.atan2(m[1], m[0])) % 360.0
    return tilt, direction


def direction_bin(direction_deg: float) -> int:
    return int(round(direction_deg / 45.0)) % 8


def cells_covered(corners_px: Sequence[np.ndarray], image_size: tuple[int, int]) -> set[tuple[int, int]]:
    """(row, col) cells of a 3x3 grid over the image that contain at least one corner."""
    width, height = image_size
    cells: set[tuple[int, int]] = set()
    for px in corners_px:
        px = np.asarray(px, np.float64).reshape(-1, 2)
        cols = np.clip((px[:, 0] * COVERAGE_GRID // width).astype(int), 0, COVERAGE_GRID - 1)
        rows = np.clip((px[:, 1] * COVERAGE_GRID // height).astype(int), 0, COVERAGE_GRID - 1)
        cells.update(zip(rows.tolist(), cols.tolist(), strict=True))
    return cells


def join_words(items: Sequence[str]) -> str:
    items = list(items)
    if not items:
        return ""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


@dataclass(frozen=True)
class SessionGeometry:
    """What the gates read from the poses: per-view geometry of the usable views and their homographies."""

    views: list[ViewGeometry]
    homographies: list[np.ndarray]  # of the usable views, undistorted through ``lens``
    unused: list[tuple[str, str]]  # (view name, reason)
    focal_px: float
    focal_source: str
    lens: SessionLens | None


def _undistorted(corners_px: np.ndarray, lens: SessionLens | None) -> np.ndarray:
    if lens is None or not np.any(lens.dist_coeffs):
        return corners_px
    K = lens.camera_matrix
    if lens.fisheye:
        return cv2.fisheye.undistortPoints(corners_px.reshape(-1, 1, 2), K, lens.dist_coeffs, P=K).reshape(
            -1, 2
        )
    return cv2.undistortPoints(corners_px.reshape(-1, 1, 2), K, lens.dist_coeffs, P=K).reshape(-1, 2)


def view_geometries(
    views: Sequence[BoardView],
    model_points: np.ndarray,
    image_size: tuple[int, int],
    focal_px: float | None = None,
) -> SessionGeometry:
    """Tilt and direction of every view that can give one (calibctl.core.capture.tilt), and their
    homographies.

    Args:
        model_points: (M, 3) or (M, 2) board model points indexed by ``corner_ids``, any unit.
        focal_px: a known focal length (held fixed); None fits one to the session
            (``estimate_focal_px`` as the start, then the small lens model), or holds the image diagonal
            when the session is too flat to tell.
    """
    model = np.asarray(model_points, np.float64)[:, :2]
    model3 = np.column_stack([model, np.zeros(len(model))])
    source = "given"
    if focal_px is None:
        raw = [
            H
            for v in views
            if len(v.corner_ids) >= MIN_TILT_CORNERS
            and (H := view_homography(model[v.corner_ids], v.corners_px)) is not None
        ]
        focal_px, source = estimate_focal_px(raw, image_size), "session"
        if focal_px is None:
            focal_px, source = math.hypot(*image_size), "nominal"
    tilts, lens = session_tilts(
        [model3[v.corner_ids] for v in views], [v.corners_px for v in views], image_size, focal_px, source
    )
    geometries, homographies, unused = [], [], []
    for view, t in zip(views, tilts, strict=True):
        H = (
            None
            if not t.used
            else view_homography(model[view.corner_ids], _undistorted(view.corners_px, lens))
        )
        if H is None or t.tilt_deg is None or t.direction_deg is None:
            unused.append((view.name, t.unused_reason or "no homography"))
            continue
        name = DIRECTION_NAMES[direction_bin(t.direction_deg)] if t.tilt_deg >= 1.0 else None
        geometries.append(
            ViewGeometry(
                view.name, t.tilt_deg, t.direction_deg, name, len(view.corner_ids), float(t.sigma_deg or 0.0)
            )
        )
        homographies.append(H)
    focal = lens.focal_px if lens is not None else float(focal_px)
    return SessionGeometry(
        geometries,
        homographies,
        unused,
        focal,
        source if lens is None or lens.source != "pinhole" else f"{source} (pinhole)",
        lens,
    )


def evaluate_gates(
    views: Sequence[BoardView],
    model_points: np.ndarray,
    image_size: tuple[int, int],
    thresholds: GateThresholds | None = None,
    focal_px: float | None = None,
    image_circle: ImageCircle | None = None,
) -> GateReport:
    """All capture gates for one session's accepted views (see the module docstring for the maths).

    ``image_circle``: the disc a circular fisheye images (core.capture.image_circle); coverage then counts
    only the cells mostly inside it. None: every cell of the grid (a pinhole or full-frame lens).
    """
    th = thresholds or GateThresholds()
    with single_threaded():  # the lens fit behind the tilts: one thread, the same digits on any machine
        geo = view_geometries(views, model_points, image_size, focal_px)
    unused_words = [f"{name}: {why}" for name, why in geo.unused]
    obs_detail: dict[str, float | int | str | list[str]] = {"views_used": len(geo.homographies)}
    if unused_words:
        obs_detail["views_not_used"] = unused_words
    results = [
        replace(_observability_gate(observability(geo.homographies, image_size), th), detail=obs_detail)
    ]

    qualifying = [g.direction_deg for g in geo.views if th.tilt_min_deg <= g.tilt_deg <= th.tilt_max_deg]
    distinct = distinct_directions(qualifying)
    results.append(_tilt_gate(distinct, qualifying, geo, th))

    cells = cells_covered([v.corners_px for v in views], image_size)
    results.append(
        _coverage_gate(cells)
        if image_circle is None
        else _circle_coverage_gate(cells, image_circle, cells_inside(image_circle, image_size, COVERAGE_GRID))
    )

    n = len(views)
    results.append(
        GateResult(
            "views",
            n >= th.min_views,
            float(n),
            float(th.min_views),
            f"{n} accepted views (need {th.min_views})",
            None if n >= th.min_views else "views.too_few",
            None
            if n >= th.min_views
            else f"capture {th.min_views - n} more view{'s' if th.min_views - n > 1 else ''}",
        )
    )

    covered = tuple(
        CELL_NAMES[r][c] for r in range(COVERAGE_GRID) for c in range(COVERAGE_GRID) if (r, c) in cells
    )
    return GateReport(
        tuple(results),
        tuple(geo.views),
        covered,
        tuple(DIRECTION_NAMES[direction_bin(d)] for d in distinct),
        geo.focal_px,
        geo.focal_source,
        tuple(geo.unused),
        geo.lens,
    )


def _observability_gate(value: float, th: GateThresholds) -> GateResult:
    ok = value >= th.observability_min
    return GateResult(
        "observability",
        ok,
        value,
        th.observability_min,
        f"sigma5/sigma1 of Zhang's V = {value:.2e} (threshold {th.observability_min:.1e})",
        None if ok else "observability.low",
        None
        if ok
        else (
            f"tilt the board {th.tilt_min_deg:.0f}-{min(40.0, th.tilt_max_deg):.0f} degrees away from "
            f"square-on, toward at least {th.tilt_directions_min} different sides; the intrinsics "
            f"are not observable from these poses (the gauge grows with the square of the tilt)"
        ),
    )


def _tilt_gate(
    distinct: Sequence[float], qualifying: Sequence[float], geo: SessionGeometry, th: GateThresholds
) -> GateResult:
    ok = len(distinct) >= th.tilt_directions_min
    too_flat = sum(g.tilt_deg < th.tilt_min_deg for g in geo.views)
    too_steep = sum(g.tilt_deg > th.tilt_max_deg for g in geo.views)
    message = (
        f"{len(distinct)} tilt direction(s) at least {DISTINCT_DIRECTION_DEG:.0f} degrees apart with views "
        "at "
        f"{th.tilt_min_deg:.0f}-{th.tilt_max_deg:.0f} degrees (need {th.tilt_directions_min}); "
        f"{too_flat} view(s) flatter, {too_steep} steeper"
    )
    if geo.unused:
        message += f"; {len(geo.unused)} view(s) too small or too sparse to read tilt"
    have = [DIRECTION_NAMES[direction_bin(d)] for d in distinct]
    detail: dict[str, float | int | str | list[str]] = {
        "directions": have,
        "views_flatter": too_flat,
        "views_steeper": too_steep,
        "views_not_used": [name for name, _ in geo.unused],
    }
    if ok:
        return GateResult(
            "tilt", True, float(len(distinct)), float(th.tilt_directions_min), message, detail=detail
        )
    compass = [45.0 * b for b in range(len(DIRECTION_NAMES))]
    wanted = [
        DIRECTION_NAMES[direction_bin(d)]
        for d in directions_to_add(qualifying, compass, th.tilt_directions_min - len(distinct))
    ]
    detail["missing_directions"] = wanted
    hint = (
        f"tilt the board toward the {join_words(wanted)} ({th.tilt_min_deg:.0f}-{th.tilt_max_deg:.0f} "
        "degrees, "
        f"that side of the board farther from the camera)"
    )
    # every 20-45 degree view's compass name: the per-image table shows them, so the hint must not deny them
    named = list(dict.fromkeys(DIRECTION_NAMES[direction_bin(d)] for d in sorted(qualifying)))
    within = [n for n in named if n not in have]
    if have and not within:
        hint += f"; the tilted views so far all lean toward the {join_words(have)} (directions count as "
        hint += f"different only {DISTINCT_DIRECTION_DEG:.0f} degrees apart)"
    elif have:
        hint += (
            f"; the tilted views so far give {len(have)} direction(s) at least {DISTINCT_DIRECTION_DEG:.0f} "
            f"degrees apart ({join_words(have)}); those toward the {join_words(within)} are within "
            f"{DISTINCT_DIRECTION_DEG:.0f} degrees of them"
        )
    return GateResult(
        "tilt",
        False,
        float(len(distinct)),
        float(th.tilt_directions_min),
        message,
        "tilt.directions",
        hint,
        detail,
    )


def _coverage_gate(cells: set[tuple[int, int]]) -> GateResult:
    total = COVERAGE_GRID * COVERAGE_GRID
    missing = [
        CELL_NAMES[r][c] for r in range(COVERAGE_GRID) for c in range(COVERAGE_GRID) if (r, c) not in cells
    ]
    message = f"corners reach {len(cells)} of {total} cells of a 3x3 grid over the image"
    detail: dict[str, float | int | str | list[str]] = {"missing_cells": missing}
    if not missing:
        return GateResult("coverage", True, float(len(cells)), float(total), message, detail=detail)
    return GateResult(
        "coverage",
        False,
        float(len(cells)),
        float(total),
        message,
        "coverage.missing_cells",
        f"cover the {join_words(missing)}",
        detail,
    )


def _circle_coverage_gate(
    cells: set[tuple[int, int]], circle: ImageCircle, inside: set[tuple[int, int]]
) -> GateResult:
    """Coverage over the cells mostly inside the image circle; the circle is recorded in the detail."""
    reached = cells & inside
    grid = [(r, c) for r in range(COVERAGE_GRID) for c in range(COVERAGE_GRID)]
    missing = [CELL_NAMES[r][c] for r, c in grid if (r, c) in inside and (r, c) not in cells]
    outside = [CELL_NAMES[r][c] for r, c in grid if (r, c) not in inside]
    message = (
        f"corners reach {len(reached)} of the {len(inside)} cells of a 3x3 grid over the image that lie "
        f"mostly inside the {circle.describe()}"
    )
    detail: dict[str, float | int | str | list[str]] = {
        "missing_cells": missing,
        "cells_outside_circle": outside,
        **circle_detail(circle),
    }
    if not missing:
        return GateResult("coverage", True, float(len(reached)), float(len(inside)), message, detail=detail)
    return GateResult(
        "coverage",
        False,
        float(len(reached)),
        float(len(inside)),
        message,
        "coverage.missing_cells",
        f"cover the {join_words(missing)} (inside the image circle)",
        detail,
    )
