"""The board in one sweep, found without a human cropping each pose.

Steps (docs/lidar.md): keep the points inside the station box (set once per station, LiDAR frame);
RANSAC a plane (seeded, so a sweep always segments the same way), refit it by least squares (SVD); on
that plane split each ring into runs at gaps and keep the largest group of runs that touch ring to
ring (the board, not the hand or a wall in the same plane); the ring runs' end points are the board's
edges. Each end point is moved outward by half the ring's point spacing: the last return on the board
lies on average half a step inside the true edge. A rectangle fitted to the end points (its angle, then
each side by least squares) gives the measured width and height, compared with the backing board
("board dimension error"). Rings come from the sweep's ``ring`` field, or by binning the elevation
angle when the sweep has none. Up to ``MAX_PLANES`` planes are tried, largest first; the first whose
outline matches the board is taken.

Outcomes per scan: ``accepted``, ``no_plane``, ``too_few_rings``, ``dimension_mismatch`` (with the
numbers; a board ~1000x too big is named as millimetres).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from calibctl.core.lidar.pcd import PointCloud

RANSAC_ITERATIONS = 300
PLANE_THRESHOLD_M = 0.03  # a VLP-16's range accuracy is +/- 3 cm
MAX_PLANES = 3
MIN_PLANE_POINTS = 30
RUN_GAP_M = 0.10  # points of one ring farther apart than this on the plane are separate runs
RING_LINK_M = 0.30  # runs of neighbouring rings closer than this belong to one object
ELEVATION_GAP_DEG = 0.4  # rings without a ring field: elevation clusters separated by more than this
EDGE_STEPS = 5  # spacing at a run's end: median of its last few steps
DEFAULT_MIN_RINGS = 7  # acfr's README: a VLP-16 needs at least 7 rings on the board
DEFAULT_MAX_DIMENSION_ERROR_M = 0.05


@dataclass(frozen=True)
class StationBox:
    """Axis-aligned region of interest in the LiDAR frame, metres: (3,) lower and upper corners."""

    lower_m: tuple[float, float, float]
    upper_m: tuple[float, float, float]

    def contains(self, points_m: np.ndarray) -> np.ndarray:
        """(N, 3) -> (N,) bool."""
        return np.all((points_m >= np.asarray(self.lower_m)) & (points_m <= np.asarray(self.upper_m)), axis=1)


@dataclass(frozen=True)
class BoardInScan:
    """What a sweep says about the board.

    Attributes:
        outcome: accepted, no_plane, too_few_rings or dimension_mismatch; message: the numbers in words.
        normal: (3,) unit plane normal, LiDAR frame, pointing away from the sensor; distance_m: n . p on the
        plane. points_m: (M, 3) board points; ring_of_point: (M,) ring index; edge_points_m: (E, 3) ring end
            points moved half a step outward, edge_ring: (E,) their rings; centre_m: (3,) rectangle centre;
            corners_m: (4, 3).
        width_m, height_m: measured sides matched to the backing board's (width <= height as registered);
        dimension_error_m: (width, height) measured - registered; rings: rings on the board;
        plane_rms_m: RMS point-to-plane distance of the board points; range_m: sensor to centre.
    """

    outcome: str
    message: str
    normal: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance_m: float = 0.0
    points_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    ring_of_point: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    edge_points_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    edge_ring: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    centre_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    corners_m: np.ndarray = field(default_factory=lambda: np.zeros((4, 3)))
    width_m: float = 0.0
    height_m: float = 0.0
    dimension_error_m: tuple[float, float] = (0.0, 0.0)
    rings: int = 0
    plane_rms_m: float = 0.0
    range_m: float = 0.0
    points_in_box: int = 0

    @property
    def accepted(self) -> bool:
        return self.outcome == "accepted"


def rings_from_elevation(points_m: np.ndarray, gap_deg: float = ELEVATION_GAP_DEG) -> np.ndarray:
    """(N, 3) -> (N,) int ring index by clustering elevation angles (for sweeps without a ring field)."""
    if len(points_m) == 0:
        return np.zeros(0, np.int64)
    elev = np.degrees(np.arctan2(points_m[:, 2], np.hypot(points_m[:, 0], points_m[:, 1])))
    order = np.argsort(elev)
    breaks = np.concatenate([[0], (np.diff(elev[order]) > gap_deg).astype(np.int64)])
    ring = np.empty(len(elev), np.int64)
    ring[order] = np.cumsum(breaks)
    return ring


def ransac_plane(
    points_m: np.ndarray,
    rng: np.random.Generator,
    threshold_m: float = PLANE_THRESHOLD_M,
    iterations: int = RANSAC_ITERATIONS,
) -> np.ndarray:
    """(N, 3) -> (N,) bool inliers of the plane with most points within ``threshold_m``."""
    n = len(points_m)
    best = np.zeros(n, bool)
    if n < 3:
        return best
    picks = rng.integers(0, n, size=(iterations, 3))
    a, b, c = points_m[picks[:, 0]], points_m[picks[:, 1]], points_m[picks[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    good = norms > 1e-9
    normals, a = normals[good] / norms[good, None], a[good]
    for chunk in range(0, len(normals), 64):  # (64, N) distances at a time
        nn, aa = normals[chunk : chunk + 64], a[chunk : chunk + 64]
        dist = np.abs(points_m @ nn.T - np.sum(nn * aa, axis=1))
        counts = (dist < threshold_m).sum(axis=0)
        k = int(np.argmax(counts))
        if counts[k] > best.sum():
            best = dist[:, k] < threshold_m
    return best


def fit_plane(points_m: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane of (N, 3) points: (unit normal pointing away from the origin, distance n . p)."""
    centroid = points_m.mean(axis=0)
    normal = np.linalg.svd(points_m - centroid, full_matrices=False)[2][2]
    if normal @ centroid < 0:
        normal = -normal
    return normal, float(normal @ centroid)


def _plane_basis(normal: np.ndarray) -> np.ndarray:
    """(2, 3) in-plane axes: u horizontal (perpendicular to LiDAR z), v up the plane."""
    up = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(up, normal)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(normal, u)])


def _runs(points_m: np.ndarray, ring: np.ndarray) -> list[np.ndarray]:
    """Indices of each ring's runs, each sorted by azimuth, split at gaps over RUN_GAP_M."""
    runs: list[np.ndarray] = []
    az = np.arctan2(points_m[:, 1], points_m[:, 0])
    for r in np.unique(ring):
        idx = np.flatnonzero(ring == r)
        a = az[idx]
        if a.max() - a.min() > np.pi:  # the run crosses the -x axis: unwrap
            a = np.where(a < 0, a + 2 * np.pi, a)
        idx = idx[np.argsort(a, kind="stable")]
        gaps = np.linalg.norm(np.diff(points_m[idx], axis=0), axis=1) > RUN_GAP_M
        runs.extend(np.split(idx, np.flatnonzero(gaps) + 1))
    return runs


def _largest_object(points_m: np.ndarray, ring: np.ndarray, runs: list[np.ndarray]) -> list[np.ndarray]:
    """The group of runs linked ring to ring (within RING_LINK_M) holding the most points."""
    label = list(range(len(runs)))

    def find(i: int) -> int:
        while label[i] != i:
            label[i] = label[label[i]]
            i = label[i]
        return i

    rings = [int(ring[r[0]]) for r in runs]
    for i in range(len(runs)):
        for j in range(i + 1, len(runs)):
            if abs(rings[i] - rings[j]) in (0, 1) and rings[i] != rings[j]:
                d = np.linalg.norm(points_m[runs[i]][:, None] - points_m[runs[j]][None], axis=2).min()
                if d < RING_LINK_M:
                    label[find(i)] = find(j)
    groups: dict[int, list[np.ndarray]] = {}
    for i, r in enumerate(runs):
        groups.setdefault(find(i), []).append(r)
    return max(groups.values(), key=lambda g: sum(len(r) for r in g))


def _edge_points(
    points_m: np.ndarray, ring: np.ndarray, runs: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Both ends of each run of >= 2 points, moved outward by half the point spacing there; their rings."""
    out, rings = [], []
    for r in runs:
        if len(r) < 2:
            continue
        p = points_m[r]
        step = np.linalg.norm(np.diff(p, axis=0), axis=1)
        # the spacing near each end (a turned board spreads its far end's points wider than its near end's)
        for end, inner, local in ((p[0], p[1], step[:EDGE_STEPS]), (p[-1], p[-2], step[-EDGE_STEPS:])):
            direction = (end - inner) / max(float(np.linalg.norm(end - inner)), 1e-12)
            out.append(end + 0.5 * float(np.median(local)) * direction)
            rings.append(int(ring[r[0]]))
    return np.asarray(out).reshape(-1, 3), np.asarray(rings, np.int64)


def fit_rectangle(edge_uv: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Rectangle through (E, 2) in-plane edge points.

    Returns:
        (angle rad of its first side to u, (2,) centre uv, (2,) side lengths along its own axes), metres.
    """

    def sides(theta: float) -> tuple[float, np.ndarray, np.ndarray]:
        c, s = np.cos(theta), np.sin(theta)
        ab = edge_uv @ np.array([[c, -s], [s, c]])
        lo, hi = ab.min(axis=0), ab.max(axis=0)
        for _ in range(5):  # assign each point to its nearest side, refit each side as a mean
            d = np.stack([ab[:, 0] - lo[0], hi[0] - ab[:, 0], ab[:, 1] - lo[1], hi[1] - ab[:, 1]], axis=1)
            side = np.argmin(np.abs(d), axis=1)
            for k, (axis, bound) in enumerate(((0, lo), (0, hi), (1, lo), (1, hi))):
                if (side == k).sum() >= 2:
                    bound[axis] = ab[side == k, axis].mean()
        cost = float(np.mean(np.min(np.abs(d), axis=1) ** 2))
        return cost, lo, hi

    grid = np.radians(np.arange(0.0, 90.0, 1.0))
    costs = [sides(t)[0] for t in grid]
    best = float(grid[int(np.argmin(costs))])
    fine = best + np.radians(np.linspace(-1.0, 1.0, 41))
    theta = float(fine[int(np.argmin([sides(t)[0] for t in fine]))])
    _, lo, hi = sides(theta)
    c, s = np.cos(theta), np.sin(theta)
    centre_ab = (lo + hi) / 2
    return theta, np.array([[c, -s], [s, c]]) @ centre_ab, hi - lo


def segment_board(
    cloud: PointCloud,
    box: StationBox,
    backing_m: tuple[float, float],
    *,
    min_rings: int = DEFAULT_MIN_RINGS,
    max_dimension_error_m: float = DEFAULT_MAX_DIMENSION_ERROR_M,
    seed: int = 0,
) -> BoardInScan:
    """Find the board of ``backing_m`` = (width, height) metres in ``cloud`` inside ``box`` (module
    docstring)."""
    inside = box.contains(cloud.points_m)
    pts = cloud.points_m[inside]
    n_box = len(pts)
    if n_box < MIN_PLANE_POINTS:
        dropped = cloud.dropped_nonfinite
        message = f"{n_box} points inside the station box (need {MIN_PLANE_POINTS})"
        if dropped and not len(cloud.points_m):
            message = (
                f"all {dropped} points of the sweep are non-finite (NaN or inf): it holds no measurement; "
                "export that sweep again from the recording"
            )
        elif dropped:
            message += f"; {dropped} of the sweep's points were non-finite (NaN or inf) and dropped"
        return BoardInScan("no_plane", message, points_in_box=n_box)
    ring = cloud.ring[inside] if cloud.ring is not None else rings_from_elevation(pts)
    rng = np.random.default_rng(seed)
    remaining = np.ones(n_box, bool)
    first: BoardInScan | None = None
    for _ in range(MAX_PLANES):
        idx = np.flatnonzero(remaining)
        if len(idx) < MIN_PLANE_POINTS:
            break
        inl = idx[ransac_plane(pts[idx], rng)]
        if len(inl) < MIN_PLANE_POINTS:
            break
        remaining[inl] = False
        result = _board_on_plane(pts, ring, inl, backing_m, min_rings, max_dimension_error_m, n_box)
        if result.accepted:
            return result
        first = first or result
    return first or BoardInScan(
        "no_plane",
        f"no plane of >= {MIN_PLANE_POINTS} points among the {n_box} points inside the station box",
        points_in_box=n_box,
    )


def _board_on_plane(
    pts: np.ndarray,
    ring: np.ndarray,
    inl: np.ndarray,
    backing_m: tuple[float, float],
    min_rings: int,
    max_err_m: float,
    n_box: int,
) -> BoardInScan:
    normal, dist = fit_plane(pts[inl])
    close = np.flatnonzero(np.abs(pts @ normal - dist) < PLANE_THRESHOLD_M)
    group = _largest_object(pts[close], ring[close], _runs(pts[close], ring[close]))
    board_idx = close[np.concatenate(group)]
    normal, dist = fit_plane(pts[board_idx])
    board, board_ring = pts[board_idx], ring[board_idx]
    rings = len(np.unique(board_ring))
    rms = float(np.sqrt(np.mean((board @ normal - dist) ** 2)))
    base = {
        "normal": normal,
        "distance_m": dist,
        "points_m": board,
        "ring_of_point": board_ring,
        "rings": rings,
        "plane_rms_m": rms,
        "points_in_box": n_box,
    }
    if rings < min_rings:
        return BoardInScan("too_few_rings", f"{rings} rings on the board plane (need {min_rings})", **base)
    local_runs = _runs(board, board_ring)
    edges, edge_ring = _edge_points(board, board_ring, local_runs)
    edges = edges - np.outer(edges @ normal - dist, normal)  # onto the plane
    basis = _plane_basis(normal)
    origin = normal * dist
    theta, centre_uv, sides = fit_rectangle((edges - origin) @ basis.T)
    c, s = np.cos(theta), np.sin(theta)
    axes = np.array([[c, s], [-s, c]]) @ basis  # the rectangle's own axes in 3D, (2, 3)
    centre = origin + centre_uv @ basis
    corners = np.array(
        [
            centre + sx * sides[0] / 2 * axes[0] + sy * sides[1] / 2 * axes[1]
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
    )
    measured = np.sort(sides)
    registered = np.array(backing_m) if backing_m[0] <= backing_m[1] else np.array(backing_m[::-1])
    error = measured - registered
    if backing_m[0] > backing_m[1]:
        measured, error = measured[::-1], error[::-1]
    result = BoardInScan(
        "accepted",
        "",
        edge_points_m=edges,
        edge_ring=edge_ring,
        centre_m=centre,
        corners_m=corners,
        width_m=float(measured[0]),
        height_m=float(measured[1]),
        dimension_error_m=(float(error[0]), float(error[1])),
        range_m=float(np.linalg.norm(centre)),
        **base,
    )
    text = (
        f"board measures {measured[0] * 1e3:.0f} x {measured[1] * 1e3:.0f} mm, registered "
        f"{backing_m[0] * 1e3:.0f} x {backing_m[1] * 1e3:.0f} mm"
    )
    ratio = float(np.mean(measured / np.array(backing_m)))
    if 300 < ratio < 3000:
        return _replace(
            result,
            "dimension_mismatch",
            f"{text}: ~{ratio:.0f}x too big, the points look like millimetres (give the scans in metres)",
        )
    if np.max(np.abs(error)) > max_err_m:
        return _replace(
            result,
            "dimension_mismatch",
            f"{text}: error {error[0] * 1e3:+.0f}, {error[1] * 1e3:+.0f} mm "
            f"(allowed +/-{max_err_m * 1e3:.0f} mm)",
        )
    return _replace(result, "accepted", f"{text} ({rings} rings, plane RMS {rms * 1e3:.1f} mm)")


def _replace(result: BoardInScan, outcome: str, message: str) -> BoardInScan:
    return replace(result, outcome=outcome, message=message)
