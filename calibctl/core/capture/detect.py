"""Board detection: chessboards (OpenCV classic, SB fallback), ChArUco and AprilGrid, sub-pixel refined.

Which chessboard detector, by measurement (benchmarks/bench_detect.py, 2026-11-23; OpenCV 5.0.0, one
thread, on a loaded 2-core machine; 20 rendered views per size through the seed lens, corner error
against the renderer's truth):

    detector                                   640x480 mean / p95 err    ms   1280x960 mean / p95     ms
    findChessboardCorners + cornerSubPix 11x11  0.045 / 0.081 px          5    0.041 / 0.076 px       17
    findChessboardCornersSB                     0.053 / 0.125 px         88    0.048 / 0.127 px      334
    findChessboardCornersSB + ACCURACY          0.039 / 0.090 px        291    0.027 / 0.065 px     1581
    calibctl detect_chessboard (below)          0.037 / 0.070 px          5    0.028 / 0.054 px       18

Recall first: wherever one plain full-resolution call (classic with ADAPTIVE_THRESH | NORMALIZE_IMAGE,
or SB) finds the board, calibctl must find it (tests/core/capture/test_detect_real.py runs the plain calls on
every real set in ../shared/datasets and compares image by image). Classic is tried first (as
accurate as SB + ACCURACY at 1/30 to 1/100 of the time), SB last (it alone finds udacity
calibration4.jpg and 5 baka-stereo boards), and both are refined with cornerSubPix at full resolution
with a half-window of 0.35 x the shortest grid edge (clamped to 2..12 px) instead of the fixed 11x11.

Speed and a bounded time per frame (``search_levels``):
  * No quick reject. ``cv2.checkChessboard`` (used until 2026-11) rejected 29 of the 60 baka-stereo
    frames, each with a board a plain call finds, on the 640 px copy it ran on (26 at full size).
  * Searches run on an integer-factor INTER_AREA copy of at most ``MAX_SEARCH_PIXELS`` (block
    averaging, fast): the image itself up to 1280x960, 1/4 of a 4000x3000 frame. At full size a
    half-size copy is searched first (3x faster when the board is big enough).
  * The classic search blows up on noise (3.5 s on 1333x1000 sensor noise), so it is skipped when
    neighbouring pixels do not correlate (``neighbour_correlation`` below ``NOISE_CORRELATION_MIN``);
    it found no board there anyway, SB still runs.
  * A refined grid must be consistent (``grid_is_consistent``), else the next level is tried: at
    half size a blurred board once gave a corner 8 px off.
  Worst board-free 4000x3000 frame: see BENCHMARKS.md (benchmarks/bench_detect.py).

Blur: the 10-90 % edge rise width of the board's edges, the larger of the medians over its
horizontal and its vertical edges (``edge_width_px``). On rendered 640x480 views (squares 20-40 px)
with Gaussian blur sigma 0.7 / 2 / 3 / 4 / 5 / 6 px the pooled median measured 2.5 / 5.5 / 8.0 / 10.5
/ 12.7 / 14.4 px and the mean corner error was 0.031 / 0.031 / 0.051 / 0.10 / 0.30 / 0.41 px. Beyond
``BLUR_MAX_EDGE_PX`` = 8.0 px the error climbs quickly (3x at 10.5 px), so such a view is "blurred".
The sharp real photos measure 1.6-5.7 px; baka-stereo boards moved during the exposure 8.3-17 px
across the motion (and about 1.6 px along it).

Corner order is canonical: rows of ``cols`` corners, the grid right-handed in the image (x right,
y down), and - when the board has an odd + even number of squares, so it is not 180-degree
symmetric - the first square (between corners 0, 1, cols, cols + 1) is black, as is the square
outside corner 0 (OpenCV's pattern.png; calibctl synth). So every detector gives the same physical
corner the same id, which stereo pairs rely on.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, replace

import cv2
import numpy as np

from calibctl.core.board.board_geometry import aprilgrid_tag_point_ids
from calibctl.core.board.board_spec import (
    APRILGRID,
    APRILGRID_BORDER_BITS,
    CHARUCO,
    BoardSpec,
    make_charuco_board,
)

MAX_SEARCH_PIXELS = 1_300_000  # 1280x960 and 1281x721 are searched at full resolution, 4000x3000 at 1/4
QUICK_SEARCH_MIN_SIDE_PX = 320
NOISE_CORRELATION_MIN = 0.5
SUBPIX_WINDOW_FRAC = 0.35
SUBPIX_HALF_WINDOW_PX = (2, 12)
SUBPIX_FALLBACK_HALF_WINDOWS_PX = (5, 3)  # OpenCV's usual 11x11, then 7x7
BLUR_MAX_EDGE_PX = 8.0
CHARUCO_MIN_CORNERS = 6
FOUND_INCONSISTENT = (
    "was found but its corners do not form a consistent grid"  # in the reason: a board, not none
)
GRID_TOL_FRAC = 0.3
CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 0.001)


@dataclass(frozen=True)
class DetectorSettings:
    max_search_pixels: int = MAX_SEARCH_PIXELS
    noise_correlation_min: float = NOISE_CORRELATION_MIN
    sb_fallback: bool = True
    blur_max_edge_px: float = BLUR_MAX_EDGE_PX
    charuco_min_corners: int = CHARUCO_MIN_CORNERS


@dataclass(frozen=True)
class Detection:
    """A detected board.

    Attributes:
        corner_ids: (N,) int64 row-major ids (``BoardSpec.object_points`` order).
        corners_px: (N, 2) float64 sub-pixel corners, full-resolution pixels, pixel centres at integers.
        method: "classic", "sb", "charuco" or "aprilgrid".
        edge_width_px: mean edge rise width (blur measure), None when not measured (partial ChArUco).
    """

    corner_ids: np.ndarray
    corners_px: np.ndarray
    method: str
    edge_width_px: float | None = None


def downscaled_to_pixels(gray: np.ndarray, max_pixels: int) -> tuple[np.ndarray, int]:
    """(copy with at most max_pixels pixels, integer factor k); the input itself (k = 1) when small enough.

    The factor is an integer so INTER_AREA takes its block-average fast path (1280x960 -> 640x480 in
    0.2 ms, against 5.5 ms for -> 1024x768). Pixel u of the copy covers full-resolution pixels
    k*u .. k*u + k - 1, so ``u_full = (u + 0.5) * k - 0.5``.
    """
    height, width = gray.shape[:2]
    k = max(1, math.ceil(math.sqrt(width * height / max_pixels)))
    while (width // k) * (height // k) > max_pixels:
        k += 1
    if k == 1:
        return gray, 1
    return cv2.resize(gray, (width // k, height // k), interpolation=cv2.INTER_AREA), k


def _grid_min_edge_px(corners_px: np.ndarray, cols: int, rows: int) -> float:
    grid = corners_px.reshape(rows, cols, 2)
    along = np.linalg.norm(np.diff(grid, axis=1), axis=2).min()
    across = np.linalg.norm(np.diff(grid, axis=0), axis=2).min()
    return float(min(along, across))


def refine_corners(
    gray: np.ndarray, corners_px: np.ndarray, min_edge_px: float, half_window_px: int | None = None
) -> np.ndarray:
    """cornerSubPix, by default with a half-window of SUBPIX_WINDOW_FRAC x the shortest grid edge
    (clamped to SUBPIX_HALF_WINDOW_PX). (N, 2) float64 in and out."""
    lo, hi = SUBPIX_HALF_WINDOW_PX
    half = half_window_px or min(max(round(SUBPIX_WINDOW_FRAC * min_edge_px), lo), hi)
    pts = np.ascontiguousarray(corners_px, dtype=np.float32).reshape(-1, 1, 2)
    refined = cv2.cornerSubPix(gray, pts, (half, half), (-1, -1), SUBPIX_CRITERIA)
    return refined.reshape(-1, 2).astype(np.float64)


def _patch_mean(gray: np.ndarray, point: np.ndarray, radius: int) -> float | None:
    x, y = int(round(point[0])), int(round(point[1]))
    height, width = gray.shape[:2]
    if not (radius <= x < width - radius and radius <= y < height - radius):
        return None
    return float(gray[y - radius : y + radius + 1, x - radius : x + radius + 1].mean())


def canonical_order(gray: np.ndarray, corners_px: np.ndarray, cols: int, rows: int) -> np.ndarray:
    """Reorder a full (cols * rows, 2) grid: right-handed, corner 0 at the black outer square."""
    grid = np.asarray(corners_px, np.float64).reshape(rows, cols, 2)
    outline = np.array([grid[0, 0], grid[0, -1], grid[-1, -1], grid[-1, 0]])
    x, y = outline[:, 0], outline[:, 1]
    if np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0:  # mirrored: flip the column order
        grid = grid[:, ::-1]
    if (cols + rows) % 2 == 0:  # 180-degree symmetric pattern: nothing tells the two ends apart
        return grid.reshape(-1, 2)
    # Square (0, 0) between corners 0, 1, cols, cols + 1 is black on the canonical board (diagonal
    # squares share a colour, so compare it with its neighbour across an edge).
    neighbour = (0, 1) if cols >= 3 else (1, 0) if rows >= 3 else None
    if neighbour is None:
        return grid.reshape(-1, 2)
    radius = max(1, int(0.15 * _grid_min_edge_px(grid.reshape(-1, 2), cols, rows)))
    first = _patch_mean(gray, grid[:2, :2].reshape(-1, 2).mean(axis=0), radius)
    r, c = neighbour
    beside = _patch_mean(gray, grid[r : r + 2, c : c + 2].reshape(-1, 2).mean(axis=0), radius)
    if first is not None and beside is not None and first > beside:
        grid = grid[::-1, ::-1]
    return grid.reshape(-1, 2)


def edge_width_px(gray: np.ndarray, corners_px: np.ndarray, cols: int, rows: int) -> float | None:
    """The board's edge rise width (10-90 %), pixels: the larger of the medians over its horizontal and
    over its vertical edges.

    ``cv2.estimateChessboardSharpness`` returns one profile per measured edge; its own summary is the
    mean, which broken profiles (glare, the frame border) pull up: on udacity calibration3.jpg most
    profiles are 2-3 px wide, a few 14-29 px, and the mean is 6.7 px. Hence medians. The two edge
    directions are kept apart because motion smears one of them only: on baka-stereo
    right_001772846896500.jpg (board moving) they measure 10.0 and 1.6 px, and a pooled median (3.1 px)
    hid the blur that dragged cornerSubPix up to 6.9 px off the grid.
    """
    pts = np.ascontiguousarray(corners_px, dtype=np.float32).reshape(-1, 1, 2)
    medians = []
    for vertical in (False, True):
        try:
            _, profiles = cv2.estimateChessboardSharpness(gray, (cols, rows), pts, 0.8, vertical, None)
        except cv2.error:
            continue
        if profiles is None or not profiles.size:
            continue
        widths = profiles.reshape(-1, 5)[:, 2]
        widths = widths[np.isfinite(widths) & (widths > 0)]
        if widths.size:
            medians.append(float(np.median(widths)))
    return max(medians) if medians else None


def grid_is_consistent(corners_px: np.ndarray, cols: int, rows: int, tol_frac: float = GRID_TOL_FRAC) -> bool:
    """True when every grid cell is close to a parallelogram: |c00 + c11 - c01 - c10| < tol x its edge.

    Perspective and lens distortion bend cells only a little: at most 0.03 of an edge on rendered
    views (tilts up to 40 degrees, seed lens), 0.13 on the real photos (right13.jpg, steeply tilted).
    A corner the coarse search put on the wrong spot (rendered, blur sigma 4 px, found at half size)
    measured 0.4.
    """
    g = np.asarray(corners_px, np.float64).reshape(rows, cols, 2)
    residual = np.linalg.norm(g[:-1, :-1] + g[1:, 1:] - g[:-1, 1:] - g[1:, :-1], axis=2)
    edge = 0.5 * (
        np.linalg.norm(g[:-1, 1:] - g[:-1, :-1], axis=2) + np.linalg.norm(g[1:, :-1] - g[:-1, :-1], axis=2)
    )
    return bool(np.all(residual < tol_frac * edge))


def _refined(
    gray: np.ndarray, image: np.ndarray, factor: int, corners: np.ndarray, cols: int, rows: int
) -> np.ndarray | None:
    """Refine corners found on ``image`` (a 1/factor copy) at its scale, then at full resolution.

    A wide window can catch the board's outer edge at an outer corner and drag it off (opencv
    right12.jpg at 0.4 x the edge: 12.6 px); if the refined grid is not consistent the usual 11x11
    window, then a 7x7 one, is tried from the same start (baka-stereo right_001772846884887.jpg, a
    steep board cut by the top of the frame: 0.301 with 11x11, 0.245 with 7x7). None when no window
    gives a consistent grid.
    """
    start = corners.reshape(-1, 2).astype(np.float64)
    for half in (None, *SUBPIX_FALLBACK_HALF_WINDOWS_PX):
        corners_px = start
        if factor > 1:
            corners_px = refine_corners(image, corners_px, _grid_min_edge_px(corners_px, cols, rows), half)
            corners_px = (corners_px + 0.5) * factor - 0.5
        corners_px = refine_corners(gray, corners_px, _grid_min_edge_px(corners_px, cols, rows), half)
        if grid_is_consistent(corners_px, cols, rows):
            return corners_px
    return None


def neighbour_correlation(gray: np.ndarray, stride: int = 4) -> float:
    """Correlation of horizontally and of vertically adjacent pixels (every ``stride``-th row / column),
    the smaller of the two.

    Sensor noise (i.i.d. per pixel) scores about 0, any photographed scene close to 1: the real
    photos in ../shared/datasets score 0.936-0.992. ``gray``: (H, W) uint8. One pass of sums over the
    sampled lines (float64) instead of centring each neighbour array: 0.26 -> 0.15 ms a call on the
    half-size copies of the renders and real photos, the value within 2e-7 of the centred float32 form.
    """
    scores = []
    for lines in (gray[::stride], gray[:, ::stride].T):  # only the sampled lines are converted
        x = lines.astype(np.float64)
        first, last = x[:, 0], x[:, -1]
        n = x.shape[0] * (x.shape[1] - 1)  # pairs (x[:, j], x[:, j + 1])
        if n == 0:  # a one-pixel-wide image has no neighbours: nothing says it is noise
            scores.append(1.0)
            continue
        total, squares = float(x.sum()), float(np.einsum("ij,ij->", x, x))
        sum_a, sum_b = total - float(last.sum()), total - float(first.sum())
        var_a = squares - float(last @ last) - sum_a * sum_a / n
        var_b = squares - float(first @ first) - sum_b * sum_b / n
        cov = float(np.einsum("ij,ij->", x[:, :-1], x[:, 1:])) - sum_a * sum_b / n
        denom = math.sqrt(max(var_a, 0.0) * max(var_b, 0.0))
        scores.append(cov / denom if denom > 0 else 1.0)
    return min(scores)


def is_one_grey_level(gray: np.ndarray) -> bool:
    """True when every pixel has the same value (a black, white or flat frame): no detector can find a board
    there. Only an exactly flat picture: the classic detector finds rendered boards of 2 grey levels'
    contrast, so no contrast floor above zero is safe."""
    lo, hi, _, _ = cv2.minMaxLoc(gray)
    return bool(lo == hi)


def search_levels(gray: np.ndarray, settings: DetectorSettings) -> list[tuple[str, np.ndarray, int]]:
    """The (method, image, integer factor) searches ``detect_chessboard`` tries, in order.

    Classic on a half-size copy (3x faster when the board is big enough; only when the search copy is
    the image itself: on a reduced copy of a larger frame the time bound matters more), classic on the
    search copy, SB on the search copy. The search copy is the image itself up to
    ``max_search_pixels``, so on every real set in ../shared/datasets the cascade ends with the very
    calls a plain loop makes. On a noise-like image (``neighbour_correlation`` below
    ``noise_correlation_min``) the classic levels are left out: there the classic detector costs
    seconds (3.5 s on 1333x1000 sensor noise) and finds nothing; on rendered boards under Gaussian
    noise it found none below a correlation of 0.59, SB found every one down to 0.11. A picture of one grey
    level (``is_one_grey_level``: a black frame, a lens cap, a blown-out white) has no level at all: its
    three searches cost 170 ms of CPU at 1280x960 (one test of the smallest copy, then of the picture, cost
    under 1 ms), and a camera that delivers black frames fills a unit with them.
    """
    search, k = downscaled_to_pixels(gray, settings.max_search_pixels)
    half = None
    if k == 1 and max(search.shape) >= 2 * QUICK_SEARCH_MIN_SIDE_PX:
        half = cv2.resize(search, (search.shape[1] // 2, search.shape[0] // 2), interpolation=cv2.INTER_AREA)
    if is_one_grey_level(half if half is not None else search) and is_one_grey_level(gray):
        return []
    levels: list[tuple[str, np.ndarray, int]] = []
    # Measured on the smallest copy, for speed: block averaging leaves i.i.d. noise uncorrelated, and a
    # scene only scores higher there, so the check can only let more images through to the classic.
    if neighbour_correlation(half if half is not None else search) >= settings.noise_correlation_min:
        if half is not None:
            levels.append(("classic", half, 2))
        levels.append(("classic", search, k))
    if settings.sb_fallback:
        levels.append(("sb", search, k))
    return levels


def detect_chessboard(
    gray: np.ndarray, cols: int, rows: int, settings: DetectorSettings | None = None
) -> tuple[Detection | None, str]:
    """Find a full cols x rows inner-corner chessboard in an 8-bit grey image.

    Search order (``search_levels``): classic on a half-size copy of the search copy; classic on the
    search copy (full resolution up to ``max_search_pixels``; skipped on a noise-like image); SB on the
    search copy. A level whose refined grid is not consistent (``grid_is_consistent``) hands over to
    the next one.

    Returns:
        (Detection, "") or (None, the reason in words).
    """
    settings = settings or DetectorSettings()
    inconsistent = False
    levels = search_levels(gray, settings)
    for method, image, factor in levels:
        if method == "classic":
            found, corners = cv2.findChessboardCorners(image, (cols, rows), flags=CLASSIC_FLAGS)
        else:
            found, corners = cv2.findChessboardCornersSB(image, (cols, rows), flags=0)
        if not found or corners is None:
            continue
        corners_px = _refined(gray, image, factor, corners, cols, rows)
        if corners_px is None:
            inconsistent = True
            continue
        corners_px = canonical_order(gray, corners_px, cols, rows)
        width = edge_width_px(gray, corners_px, cols, rows)
        return Detection(np.arange(cols * rows, dtype=np.int64), corners_px, method, width), ""
    if inconsistent:
        return None, (f"a {cols}x{rows} chessboard {FOUND_INCONSISTENT} (blurred, bent or partly hidden?)")
    methods = {method for method, _, _ in levels}
    if not levels and is_one_grey_level(gray):
        return (
            None,
            f"no {cols}x{rows} chessboard found (the picture is one flat grey level: lens cap, no light?)",
        )
    if "classic" not in methods:
        tried = (
            "SB detector; the classic one skipped, the image is noise-like" if methods else "no detector run"
        )
        return None, f"no {cols}x{rows} chessboard found ({tried})"
    tried = "classic and SB detectors" if "sb" in methods else "classic detector"
    return None, f"no {cols}x{rows} chessboard found ({tried}); is the whole board in the frame?"


_local = threading.local()


def _charuco_detector(spec: BoardSpec) -> cv2.aruco.CharucoDetector:
    """One detector per board and thread (OpenCV does not promise detectBoard is thread-safe)."""
    cache: dict[BoardSpec, cv2.aruco.CharucoDetector] = _local.__dict__.setdefault("charuco", {})
    if spec not in cache:
        params = cv2.aruco.DetectorParameters()
        params.detectInvertedMarker = spec.inverted  # reads white-on-black markers too (both polarities)
        cache[spec] = cv2.aruco.CharucoDetector(
            make_charuco_board(spec), cv2.aruco.CharucoParameters(), params
        )
    return cache[spec]


OTHER_DICTIONARIES = (
    "DICT_4X4_1000",
    "DICT_5X5_1000",
    "DICT_6X6_1000",
    "DICT_7X7_1000",
    "DICT_ARUCO_ORIGINAL",
)
"""Tried when the declared dictionary reads no marker (a dictionary's smaller sets are its prefixes)."""


@dataclass(frozen=True)
class VariantCounts:
    """What each ChArUco variant finds on some frames: markers of the declared dictionary read normal only and
    with inverted markers too, corners the declared and the other layout (legacy or not) interpolate, and
    markers of other dictionaries (only looked for when the declared one reads none)."""

    frames: int
    markers_normal: int = 0
    markers_inverted: int = 0
    corners_declared: int = 0
    corners_other_layout: int = 0
    other_dictionaries: tuple[tuple[str, int], ...] = ()


def charuco_variant_counts(grays: list[np.ndarray], spec: BoardSpec) -> VariantCounts:
    """Count what each variant of ``spec`` (polarity, layout, dictionary) finds on ``grays``."""
    normal, inverted, declared, other = 0, 0, 0, 0
    flipped = replace(spec, inverted=True, legacy_pattern=not spec.legacy_pattern)
    searches = [downscaled_to_pixels(gray, MAX_SEARCH_PIXELS)[0] for gray in grays]
    for search in searches:
        _, _, _, ids = _charuco_detector(replace(spec, inverted=False)).detectBoard(search)
        normal += 0 if ids is None else len(ids)
        corners, _, _, ids = _charuco_detector(replace(spec, inverted=True)).detectBoard(search)
        inverted += 0 if ids is None else len(ids)
        declared += 0 if corners is None else len(corners)  # inverted finds the normal ones too
        corners, _, _, _ = _charuco_detector(flipped).detectBoard(search)
        other += 0 if corners is None else len(corners)
    counts = VariantCounts(len(grays), normal, inverted, declared, other)
    if inverted:
        return counts
    found = []
    for name in OTHER_DICTIONARIES:
        if name == spec.dictionary:
            continue
        variant = replace(spec, dictionary=name, inverted=True)
        n = 0
        for search in searches:
            _, _, _, ids = _charuco_detector(variant).detectBoard(search)
            n += 0 if ids is None else len(ids)
        if n:
            found.append((name, n))
    return replace(counts, other_dictionaries=tuple(found))


def charuco_variant_advice(counts: VariantCounts, spec: BoardSpec) -> str | None:
    """What was seen instead of the declared ChArUco variant, and the declaration that fits, in words; None
    when the declared variant is what the frames show (or nothing better was found)."""
    seen = (
        f"on {counts.frames} frame(s): {counts.markers_normal} markers with {spec.dictionary} normal; "
        f"{counts.markers_inverted} with inverted"
    )
    if not spec.inverted and counts.markers_inverted > max(2 * counts.markers_normal, 4):
        return f"{seen}: declare --inverted (white markers on black)"
    if counts.markers_inverted == 0:
        if counts.other_dictionaries:
            best, n = max(counts.other_dictionaries, key=lambda item: item[1])
            return f"{seen}; {n} markers with {best}: declare --dictionary {best}"
        return None
    declared_corners = counts.corners_declared
    if counts.corners_other_layout > max(2 * declared_corners, 6):
        flag = "drop --legacy" if spec.legacy_pattern else "declare --legacy (OpenCV < 4.6 layout)"
        return (
            f"{seen}; {declared_corners} corners with the declared layout, "
            f"{counts.corners_other_layout} with the {'current' if spec.legacy_pattern else 'legacy'} one: "
            f"{flag}"
        )
    return None


# CharucoDetector before OpenCV 4.14 returns every corner shifted by exactly (+0.5, +0.5) px: it
# moves the guess by -0.5 before cornerSubPix and back by +0.5 after (opencv/opencv#25539, fixed by
# #28380). Renders measured +0.48/+0.49 px mean on 4.10 and 4.13, -0.005/+0.002 px on 4.14 and 5.0.
_CHARUCO_SHIFT_PX = 0.5 if tuple(int(p) for p in cv2.__version__.split(".")[:2]) < (4, 14) else 0.0


def detect_charuco(
    gray: np.ndarray, spec: BoardSpec, settings: DetectorSettings | None = None
) -> tuple[Detection | None, str]:
    """Find ChArUco corners (partial views allowed) with cv2.aruco.CharucoDetector.

    A view counts when it has at least ``charuco_min_corners`` corners spanning two rows and two
    columns (collinear corners do not define the board plane).
    """
    settings = settings or DetectorSettings()
    search, k = downscaled_to_pixels(gray, settings.max_search_pixels)
    corners, ids, _, marker_ids = _charuco_detector(spec).detectBoard(search)
    n_markers = 0 if marker_ids is None else len(marker_ids)
    if ids is None or len(ids) < settings.charuco_min_corners:
        n = 0 if ids is None else len(ids)
        return None, (
            f"no ChArUco board: {n} corners from {n_markers} markers (need {settings.charuco_min_corners})"
        )
    ids = ids.reshape(-1).astype(np.int64)
    order = np.argsort(ids)
    ids, corners_px = ids[order], corners.reshape(-1, 2).astype(np.float64)[order] - _CHARUCO_SHIFT_PX
    if len(set((ids // spec.cols).tolist())) < 2 or len(set((ids % spec.cols).tolist())) < 2:
        return None, f"ChArUco corners all on one line ({len(ids)} corners): the board plane is undefined"
    if k != 1:
        model = spec.object_points()[ids, :2] / spec.square_size_m
        near = np.linalg.norm(model[:, None] - model[None], axis=2)
        step_px = np.linalg.norm(corners_px[:, None] - corners_px[None], axis=2)[np.isclose(near, 1.0)]
        min_edge = float(step_px.min()) * k if step_px.size else 8.0 * k
        corners_px = refine_corners(gray, (corners_px + 0.5) * k - 0.5, min_edge)
    return Detection(ids, corners_px, "charuco", None), ""


def _aprilgrid_detector(spec: BoardSpec, refine: int, constant: int) -> cv2.aruco.ArucoDetector:
    """One AprilTag detector per board, corner refinement, threshold constant and thread."""
    key = (spec, refine, constant)
    cache: dict[tuple[BoardSpec, int, int], cv2.aruco.ArucoDetector] = _local.__dict__.setdefault(
        "aprilgrid", {}
    )
    if key not in cache:
        params = cv2.aruco.DetectorParameters()
        params.markerBorderBits = APRILGRID_BORDER_BITS
        params.cornerRefinementMethod = refine
        params.adaptiveThreshConstant = constant
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, str(spec.dictionary)))
        cache[key] = cv2.aruco.ArucoDetector(dictionary, params)
    return cache[key]


def _aprilgrid_markers(search: np.ndarray, spec: BoardSpec, refine: int) -> tuple[np.ndarray, np.ndarray]:
    """(N,) tag ids and (N, 4, 2) corners of the tags read once (a tag read twice is not this grid's),
    thresholded with a constant of ``APRILGRID_THRESH_FRACTION`` of the image's contrast."""
    lo, hi = np.percentile(search[::4, ::4], (5, 95))
    constant = max(2, round(APRILGRID_THRESH_FRACTION * float(hi - lo)))
    found, found_ids, _ = _aprilgrid_detector(spec, refine, constant).detectMarkers(search)
    if found_ids is None:
        return np.zeros(0, np.int64), np.zeros((0, 4, 2))
    ids = found_ids.reshape(-1).astype(np.int64)
    corners = np.asarray(found, np.float64).reshape(-1, 4, 2)
    once = np.array([np.count_nonzero(ids == tag) == 1 for tag in ids], bool)
    return ids[once], corners[once]


# Which AprilGrid settings, by measurement (12 rendered 640x480 views of a 6x6-tag grid, tagSpacing 0.3,
# seed lens, OpenCV 5.0.0; error against the renderer's truth; 1728 corners in all):
#
#   cv2.aruco corner refinement, then                found    mean / p95 / max err      ms a view
#   NONE, adaptiveThreshConstant 7 (OpenCV's)         73 %    2.29 / 3.53 px raw            39
#   NONE, adaptiveThreshConstant 30                   95 %    1.35 / 1.80 / 2.22 px raw     38
#   NONE, constant 30, + calibctl cornerSubPix        95 %    0.041 / 0.077 / 0.14 px       46
#   SUBPIX, constant 30, + calibctl cornerSubPix      95 %    0.041 / 0.077 / 0.14 px       43
#   APRILTAG                                          19 %    0.66 / 0.89 px, (+0.46, +0.47) bias  223
#   APRILTAG + calibctl cornerSubPix                  19 %    0.036 / 0.067 / 0.09 px      199
#
# The tag corners are X-junctions with the black corner squares Kalibr prints, so the grey pixel where a
# tag touches its corner square joins the two into one contour at OpenCV's threshold constant and the tag
# is lost; a higher constant keeps it white. A fixed 30 lost every tag of dim renders (gain 40 of 255: 0
# of 864 corners), so the constant is a fraction of the image's contrast (its 5-95 % grey range): 0.15
# found 96 % of the 12 views' corners, 99 % of 6 views at gain 80 and 91 % at gain 40 (OpenCV's 7: 63 %
# and 99.5 %), errors as above (max 0.14 / 0.20 / 0.25 px); a second search at 0.035 of the contrast
# added 1 % for twice the time. The refined corner is cornerSubPix's with a half-window of 0.8 x the
# smaller of the tag's two-bit border (0.2 of its edge) and the gap between tags.
# OpenCV's marker image of a tag is Kalibr's print turned by 180 degrees, so the detector's corners
# (the marker's top-left, top-right, bottom-right, bottom-left) are the printed tag's bottom-right,
# bottom-left, top-left and top-right: Kalibr's pIdx columns 1, 0, 3, 2 - the mapping Kalibr's own
# cv2.aruco detector makes (GridCalibrationTargetAprilgridv2::computeObservation).
_ARUCO_TO_KALIBR_CORNER = (1, 0, 3, 2)
APRILGRID_REFINE = cv2.aruco.CORNER_REFINE_NONE
APRILGRID_THRESH_FRACTION = 0.15
APRILGRID_MIN_SYMMETRY = 0.95
"""A refined AprilGrid corner is kept when its patch is this point-symmetric (``point_symmetry``): the 1648
corners of the 12 views above score 0.989-1.000; on 6 renders with half the grid behind a grey card the
corners cornerSubPix dragged 0.8-4.7 px off score -0.08 to 0.89."""


def detect_aprilgrid(
    gray: np.ndarray, spec: BoardSpec, settings: DetectorSettings | None = None, refine: int | None = None
) -> tuple[Detection | None, str]:
    """Find the tags of a Kalibr AprilGrid with cv2.aruco's AprilTag dictionary; four corners per tag, ids
    as Kalibr numbers them (``board_geometry.aprilgrid_tag_point_ids``). Partial views allowed, as for
    ChArUco: at least ``charuco_min_corners`` corners spanning two rows and two columns.
    """
    settings = settings or DetectorSettings()
    search, k = downscaled_to_pixels(gray, settings.max_search_pixels)
    method = APRILGRID_REFINE if refine is None else refine
    tag_ids, marker_corners = _aprilgrid_markers(search, spec, method)
    tag_cols, tag_rows = spec.tags
    n_tags = tag_cols * tag_rows
    mine = tag_ids < n_tags
    if 4 * int(mine.sum()) < settings.charuco_min_corners:
        return None, (
            f"no AprilGrid: {int(mine.sum())} of its {n_tags} {spec.dictionary} tags read "
            f"({len(tag_ids)} markers; need {settings.charuco_min_corners} corners)"
        )
    corners = marker_corners[mine]
    ids = aprilgrid_tag_point_ids(tag_ids[mine], spec.cols)[:, _ARUCO_TO_KALIBR_CORNER].reshape(-1)
    corners_px = (corners.reshape(-1, 2) + 0.5) * k - 0.5
    order = np.argsort(ids)
    ids, corners_px = ids[order], corners_px[order]
    if len(set((ids // spec.cols).tolist())) < 2 or len(set((ids % spec.cols).tolist())) < 2:
        return None, f"AprilGrid corners all on one line ({len(ids)} corners): the board plane is undefined"
    tag_px = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).min() * k
    half = round(0.8 * min(0.2, spec.tag_spacing or 0.2) * tag_px)
    half = min(max(half, SUBPIX_HALF_WINDOW_PX[0]), SUBPIX_HALF_WINDOW_PX[1])
    corners_px = refine_corners(gray, corners_px, tag_px, half)
    keep = np.array([point_symmetry(gray, p, half) >= APRILGRID_MIN_SYMMETRY for p in corners_px], bool)
    return Detection(ids[keep], corners_px[keep], "aprilgrid", None), ""


def point_symmetry(gray: np.ndarray, point_px: np.ndarray, half: int) -> float:
    """Correlation of the (2 half + 1)^2 patch around ``point_px`` with itself turned by 180 degrees.

    An X-junction (a tag corner touching its corner square) is point-symmetric, so it scores near 1; a
    corner cornerSubPix dragged onto something else (an occluder's edge, the frame border) scores low.
    """
    size = 2 * half + 1
    patch = cv2.getRectSubPix(gray, (size, size), (float(point_px[0]), float(point_px[1]))).astype(np.float64)
    a = patch - patch.mean()
    b = a[::-1, ::-1]
    denom = math.sqrt(float((a * a).sum()) * float((b * b).sum()))
    return float((a * b).sum()) / denom if denom > 0 else 0.0


def detect_board(
    gray: np.ndarray, spec: BoardSpec, settings: DetectorSettings | None = None
) -> tuple[Detection | None, str]:
    """Dispatch on the board kind. ``gray``: (H, W) uint8."""
    if spec.kind == CHARUCO:
        return detect_charuco(gray, spec, settings)
    if spec.kind == APRILGRID:
        return detect_aprilgrid(gray, spec, settings)
    return detect_chessboard(gray, spec.cols, spec.rows, settings)
