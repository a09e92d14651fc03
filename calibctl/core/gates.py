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
    about 1% (tests/core/test_gates.py). A centred, Hartley-style normalisation was tried and rejected:
    it is also resolution-free but changes the value by ~300x and not by a constant factor, so the
    seed's 1e-4 threshold would no longer mean what chapter 1 measured.

Tilt is measured from the same homographies: with a nominal K (principal point at the image centre,
square pixels, focal length fitted to the session's homographies in closed form - Zhang's constraints
with only f free - or the image diagonal when the session is too flat to tell), r1 and r2 are the
normalised columns of K^-1 H and the board normal is r1 x r2. The tilt is the angle between the normal
and the optical axis. The tilt *direction* is the image direction (x right, y down) of the board side
that is farther from the camera, binned into 8 compass sectors named like "top left". Both are
exact through a pinhole (tests/core/test_gates.py); through the seed lens (k1 = -0.28, corners not
undistorted, since the lens is not known yet) the tilt reads within 7 deg of the truth (sd 3 deg,
60 rendered poses) and the direction within 15 deg.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from calibctl.core.views import BoardView

# Defaults (mirrors calibctl.config.GateThresholds; core may not import config).
OBSERVABILITY_MIN = 1e-4
TILT_MIN_DEG = 20.0
TILT_MAX_DEG = 45.0
TILT_DIRECTIONS_MIN = 3
MIN_VIEWS = 8
REFERENCE_LONG_SIDE_PX = 640.0
COVERAGE_GRID = 3

DIRECTION_NAMES = ("right", "bottom right", "bottom", "bottom left", "left", "top left", "top", "top right")
CELL_NAMES = (("top-left corner", "top edge", "top-right corner"),
              ("left edge", "centre", "right edge"),
              ("bottom-left corner", "bottom edge", "bottom-right corner"))


@dataclass(frozen=True)
class GateThresholds:
    observability_min: float = OBSERVABILITY_MIN
    tilt_min_deg: float = TILT_MIN_DEG
    tilt_max_deg: float = TILT_MAX_DEG
    tilt_directions_min: int = TILT_DIRECTIONS_MIN
    min_views: int = MIN_VIEWS

    def __post_init__(self) -> None:
        # The tilt gate counts 8 compass bins; asking for more than 8 directions can never pass.
        if not 1 <= self.tilt_directions_min <= len(DIRECTION_NAMES):
            raise ValueError(f"tilt_directions_min must be 1-{len(DIRECTION_NAMES)}, got {self.tilt_directions_min}")


@dataclass(frozen=True)
class ViewGeometry:
    """Per-view pose summary. ``direction_name`` is None when the board is square-on (tilt < 1 deg)."""

    name: str
    tilt_deg: float
    direction_deg: float
    direction_name: str | None
    n_corners: int


@dataclass(frozen=True)
class GateResult:
    """One gate. ``reason`` is a machine-readable code when it failed, ``hint`` tells the operator what to do."""

    gate: str
    passed: bool
    value: float
    threshold: float
    message: str
    reason: str | None = None
    hint: str | None = None
    detail: dict[str, float | int | str | list[str]] = field(default_factory=dict)


@dataclass(frozen=True)
class GateReport:
    gates: tuple[GateResult, ...]
    views: tuple[ViewGeometry, ...]
    covered_cells: tuple[str, ...]
    tilt_directions: tuple[str, ...]
    focal_px: float
    focal_source: str

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
    return np.array([H[0, i] * H[0, j], H[0, i] * H[1, j] + H[1, i] * H[0, j], H[1, i] * H[1, j],
                     H[2, i] * H[0, j] + H[0, i] * H[2, j], H[2, i] * H[1, j] + H[1, i] * H[2, j],
                     H[2, i] * H[2, j]])


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
        for a, b in ((h1[0] * h2[0] + h1[1] * h2[1], h1[2] * h2[2]),
                     (h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2, h1[2] ** 2 - h2[2] ** 2)):
            num -= a * b
            den += b * b
    if den * diag ** 4 < 1e-6 or num <= 0:
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


def pick_missing_directions(have: set[int], count: int) -> list[int]:
    """Direction bins to ask for next: greedily the ones farthest from every direction collected."""
    chosen: list[int] = []
    taken = set(have)
    for _ in range(max(0, count)):
        def spread(b: int) -> int:
            return min((min((b - h) % 8, (h - b) % 8) for h in taken), default=8)
        best = max((b for b in range(8) if b not in taken), key=lambda b: (spread(b), -b), default=None)
        if best is None:
            break
        chosen.append(best)
        taken.add(best)
    return chosen


def join_words(items: Sequence[str]) -> str:
    items = list(items)
    if not items:
        return ""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def view_geometries(views: Sequence[BoardView], model_points: np.ndarray, image_size: tuple[int, int],
                    focal_px: float | None = None) -> tuple[list[ViewGeometry], list[np.ndarray], float, str]:
    """Homography, tilt and direction of every view with >= 4 corners.

    Args:
        model_points: (M, 3) or (M, 2) board model points indexed by ``corner_ids``, any unit.
        focal_px: a known focal length; None fits one to the session (``estimate_focal_px``) and falls
            back to the image diagonal.

    Returns:
        (geometries, homographies, focal_px used, where it came from: "given", "session" or "nominal").
    """
    model = np.asarray(model_points, np.float64)[:, :2]
    named: list[tuple[BoardView, np.ndarray]] = []
    for view in views:
        H = view_homography(model[view.corner_ids], view.corners_px) if len(view.corner_ids) >= 4 else None
        if H is not None:
            named.append((view, H))
    homographies = [H for _, H in named]
    source = "given"
    if focal_px is None:
        focal_px, source = estimate_focal_px(homographies, image_size), "session"
        if focal_px is None:
            focal_px, source = math.hypot(*image_size), "nominal"
    geometries = []
    for view, H in named:
        tilt, direction = view_tilt(H, image_size, focal_px)
        name = DIRECTION_NAMES[direction_bin(direction)] if tilt >= 1.0 else None
        geometries.append(ViewGeometry(view.name, tilt, direction, name, len(view.corner_ids)))
    return geometries, homographies, float(focal_px), source


def evaluate_gates(views: Sequence[BoardView], model_points: np.ndarray, image_size: tuple[int, int],
                   thresholds: GateThresholds | None = None, focal_px: float | None = None) -> GateReport:
    """All capture gates for one session's accepted views (see the module docstring for the maths)."""
    th = thresholds or GateThresholds()
    geometries, homographies, focal, source = view_geometries(views, model_points, image_size, focal_px)
    results = [replace(_observability_gate(observability(homographies, image_size), th),
                       detail={"views_used": len(homographies)})]

    qualifying = [g for g in geometries if th.tilt_min_deg <= g.tilt_deg <= th.tilt_max_deg]
    have = {direction_bin(g.direction_deg) for g in qualifying}
    results.append(_tilt_gate(have, geometries, th))

    cells = cells_covered([v.corners_px for v in views], image_size)
    results.append(_coverage_gate(cells))

    n = len(views)
    results.append(GateResult(
        "views", n >= th.min_views, float(n), float(th.min_views),
        f"{n} accepted views (need {th.min_views})",
        None if n >= th.min_views else "views.too_few",
        None if n >= th.min_views else f"capture {th.min_views - n} more view{'s' if th.min_views - n > 1 else ''}"))

    covered = tuple(CELL_NAMES[r][c] for r in range(COVERAGE_GRID) for c in range(COVERAGE_GRID) if (r, c) in cells)
    return GateReport(tuple(results), tuple(geometries), covered,
                      tuple(DIRECTION_NAMES[b] for b in sorted(have)), focal, source)


def _observability_gate(value: float, th: GateThresholds) -> GateResult:
    ok = value >= th.observability_min
    return GateResult(
        "observability", ok, value, th.observability_min,
        f"sigma5/sigma1 of Zhang's V = {value:.2e} (threshold {th.observability_min:.1e})",
        None if ok else "observability.low",
        None if ok else (f"tilt the board {th.tilt_min_deg:.0f}-{min(40.0, th.tilt_max_deg):.0f} degrees away from "
                         f"square-on, toward at least {th.tilt_directions_min} different sides; the intrinsics "
                         f"are not observable from these poses (the gauge grows with the square of the tilt)"))


def _tilt_gate(have: set[int], geometries: Sequence[ViewGeometry], th: GateThresholds) -> GateResult:
    ok = len(have) >= th.tilt_directions_min
    too_flat = sum(g.tilt_deg < th.tilt_min_deg for g in geometries)
    too_steep = sum(g.tilt_deg > th.tilt_max_deg for g in geometries)
    message = (f"{len(have)} tilt direction(s) with views at {th.tilt_min_deg:.0f}-{th.tilt_max_deg:.0f} degrees "
               f"(need {th.tilt_directions_min}); {too_flat} view(s) flatter, {too_steep} steeper")
    detail: dict[str, float | int | str | list[str]] = {
        "directions": [DIRECTION_NAMES[b] for b in sorted(have)], "views_flatter": too_flat, "views_steeper": too_steep}
    if ok:
        return GateResult("tilt", True, float(len(have)), float(th.tilt_directions_min), message, detail=detail)
    wanted = [DIRECTION_NAMES[b] for b in pick_missing_directions(have, th.tilt_directions_min - len(have))]
    detail["missing_directions"] = wanted
    hint = (f"tilt the board toward the {join_words(wanted)} ({th.tilt_min_deg:.0f}-{th.tilt_max_deg:.0f} degrees, "
            f"that side of the board farther from the camera)")
    return GateResult("tilt", False, float(len(have)), float(th.tilt_directions_min), message,
                      "tilt.directions", hint, detail)


def _coverage_gate(cells: set[tuple[int, int]]) -> GateResult:
    total = COVERAGE_GRID * COVERAGE_GRID
    missing = [CELL_NAMES[r][c] for r in range(COVERAGE_GRID) for c in range(COVERAGE_GRID) if (r, c) not in cells]
    message = f"corners reach {len(cells)} of {total} cells of a 3x3 grid over the image"
    detail: dict[str, float | int | str | list[str]] = {"missing_cells": missing}
    if not missing:
        return GateResult("coverage", True, float(len(cells)), float(total), message, detail=detail)
    return GateResult("coverage", False, float(len(cells)), float(total), message, "coverage.missing_cells",
                      f"cover the {join_words(missing)}", detail)
