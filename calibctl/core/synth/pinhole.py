"""Ground-truth board photos: a pinhole + Brown-Conrady camera that renders by ray casting.

Every pixel is traced backwards: its centre is undistorted to a ray (fixed-point inverse of
Brown-Conrady, iterated to 1e-12 and checked by re-distorting), the ray is intersected with the board
plane, and the printed pattern is evaluated there. Pixels whose footprint straddles a pattern edge are
anti-aliased with ``supersample``**2 sub-samples in an n-rooks pattern; sub-sample rays come from the
local Jacobian of the ray map (within 3e-4 px of the exact inverse at the corners of the seed lens).
The other pixels take the value at their centre. Then Gaussian optical blur, shot + read noise and
8-bit quantisation.

Conventions: pixel centres at integer coordinates (OpenCV); the board frame has its origin at the first
inner corner, x along the columns, y along the rows, z = 0 on the printed face (``board_geometry``);
``T_cam_board`` (4, 4) maps board points into the camera frame. The true corners are
``cv2.projectPoints`` of the model points, so truth and renderer share one camera model.

The printed chessboard has ``cols + 1`` x ``rows + 1`` squares; the square outside corner 0 is black,
and a white quiet zone of ``margin_squares`` squares surrounds the pattern. An AprilGrid is printed as
kalibr_create_target_pdf prints it: each tag with a two-bit black border, its top toward the board's
``+y``, and a black square of the gap's size at each of its corners; there a "square" is the tag edge.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import cv2
import numpy as np

from calibctl.core.board.board_spec import (
    APRILGRID,
    APRILGRID_BORDER_BITS,
    CHARUCO,
    BoardSpec,
    make_charuco_board,
)

# The seed's reference rig (chapter 0 YAML, fitted at 640x480): f = 800 px, c = image centre.
SEED_IMAGE_SIZE = (640, 480)
SEED_FOCAL_PX = 800.0
SEED_DIST = (-0.2814, 0.0977, 0.0001, -0.0002, -0.0163)

BLACK_REFLECTANCE = 0.06
WHITE_REFLECTANCE = 0.90
CHARUCO_TEXTURE_PX_PER_SQUARE = 64
APRILGRID_TEXTURE_PX_PER_TAG = 100


def aprilgrid_texture(board: BoardSpec, px_per_tag: int = APRILGRID_TEXTURE_PX_PER_TAG) -> np.ndarray:
    """(H, W) uint8 print of an AprilGrid, row index growing with the board's ``y``; its pixel 0 starts at
    ``-tag_spacing`` tags on both axes (the corner squares outside tag 0)."""
    assert board.tag_spacing is not None and board.dictionary is not None
    tag_cols, tag_rows = board.tags
    gap, pitch = board.tag_spacing * px_per_tag, (1.0 + board.tag_spacing) * px_per_tag
    size = (round(tag_rows * pitch + gap), round(tag_cols * pitch + gap))
    img = np.full(size, 255, np.uint8)
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    g = round(gap)
    for n in range(tag_cols * tag_rows):
        x0, y0 = round(gap + (n % tag_cols) * pitch), round(gap + (n // tag_cols) * pitch)
        marker = cv2.aruco.generateImageMarker(dictionary, n, px_per_tag, borderBits=APRILGRID_BORDER_BITS)
        # Kalibr prints OpenCV's marker turned by 180 degrees, its top toward +y; rows here grow with y
        img[y0 : y0 + px_per_tag, x0 : x0 + px_per_tag] = marker[:, ::-1]
        for cy in (y0 - g, y0 + px_per_tag):
            for cx in (x0 - g, x0 + px_per_tag):
                img[cy : cy + g, cx : cx + g] = 0
    return img


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole + Brown-Conrady (k1, k2, p1, p2, k3, OpenCV order), distortion in normalised coordinates.

    Attributes:
        K: (3, 3) float64 intrinsic matrix, pixels.
        dist: (5,) float64 k1, k2, p1, p2, k3.
        image_size: (width, height) pixels.
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]

    @classmethod
    def seed_reference(cls, image_size: tuple[int, int] = SEED_IMAGE_SIZE) -> PinholeCamera:
        """The seed's lens read out at ``image_size``: K scales with the readout, distortion does not."""
        width, height = image_size
        scale = width / SEED_IMAGE_SIZE[0]
        f = SEED_FOCAL_PX * scale
        K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls(K, np.array(SEED_DIST, dtype=np.float64), (int(width), int(height)))

    def key(self) -> tuple[float, ...]:
        return (
            *np.asarray(self.K, float).ravel().tolist(),
            *np.asarray(self.dist, float).tolist(),
            float(self.image_size[0]),
            float(self.image_size[1]),
        )

    def project(self, points_board_m: np.ndarray, T_cam_board: np.ndarray) -> np.ndarray:
        """(N, 3) board points -> (N, 2) float64 distorted pixels (cv2.projectPoints)."""
        rvec, tvec = rvec_tvec(T_cam_board)
        px, _ = cv2.projectPoints(
            np.asarray(points_board_m, np.float64).reshape(-1, 1, 3),
            rvec,
            tvec,
            np.asarray(self.K, np.float64),
            np.asarray(self.dist, np.float64),
        )
        return px.reshape(-1, 2)


def rvec_tvec(T_cam_board: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(4, 4) transform -> OpenCV (3,) rvec (rad) and (3,) tvec (m)."""
    rvec, _ = cv2.Rodrigues(np.asarray(T_cam_board, np.float64)[:3, :3])
    return rvec.reshape(3), np.asarray(T_cam_board, np.float64)[:3, 3].copy()


def transform_from(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """OpenCV rvec (rad) + tvec (m) -> (4, 4) float64 T_cam_board."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, np.float64).reshape(3)
    return T


def undistort_normalised(
    xd: np.ndarray, yd: np.ndarray, dist: np.ndarray, iterations: int = 100, tol: float = 1e-12
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse Brown-Conrady by fixed-point iteration. Arrays of distorted normalised coords -> ideal."""
    k1, k2, p1, p2, k3 = (float(v) for v in dist)
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x_new, y_new = (xd - dx) / radial, (yd - dy) / radial
        step = max(float(np.max(np.abs(x_new - x))), float(np.max(np.abs(y_new - y))))
        x, y = x_new, y_new
        if step < tol:
            break
    return x, y


def distort_normalised(x: np.ndarray, y: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward Brown-Conrady on ideal normalised coords."""
    k1, k2, p1, p2, k3 = (float(v) for v in dist)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )


@lru_cache(maxsize=4)
def _ray_map(key: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    """Per-pixel ideal normalised ray (x, y) and its Jacobian wrt (u, v); invalid where not invertible."""
    K = np.array(key[:9]).reshape(3, 3)
    dist = np.array(key[9:14])
    width, height = int(key[14]), int(key[15])
    u, v = np.meshgrid(
        np.arange(-1, width + 1, dtype=np.float64), np.arange(-1, height + 1, dtype=np.float64)
    )
    yd = (v - K[1, 2]) / K[1, 1]
    xd = (u - K[0, 2] - K[0, 1] * yd) / K[0, 0]
    x, y = undistort_normalised(xd, yd, dist)
    xr, yr = distort_normalised(x, y, dist)
    valid = (np.abs(xr - xd) < 1e-9) & (np.abs(yr - yd) < 1e-9)
    # central differences on the padded grid, then crop the padding
    return padded_ray_map(x, y, np.broadcast_to(1.0, x.shape), valid)


def padded_ray_map(x: np.ndarray, y: np.ndarray, z: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, ...]:
    """Rays (x, y, z) (any positive scale) on a grid padded by one pixel all round -> the cropped ray map
    (x, y, z, x_u, x_v, y_u, y_v, z_u, z_v, valid): central differences wrt (u, v), valid where the pixel
    and its four neighbours are."""
    derivatives = []
    for a in (x, y, z):
        derivatives += [(a[1:-1, 2:] - a[1:-1, :-2]) / 2, (a[2:, 1:-1] - a[:-2, 1:-1]) / 2]
    crop = (slice(1, -1), slice(1, -1))
    valid = valid[crop] & valid[:-2, 1:-1] & valid[2:, 1:-1] & valid[1:-1, :-2] & valid[1:-1, 2:]
    return x[crop], y[crop], z[crop], *derivatives, valid


def _board_coords(
    G: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays (x, y, z), any positive scale, so also behind the camera plane (z <= 0, a fisheye past 90 deg)
    -> board-plane coords (square units) and a front-facing mask. G: inverse plane map."""
    w = G[2, 0] * x + G[2, 1] * y + G[2, 2] * z
    front = w > 1e-12
    w = np.where(front, w, 1.0)
    return (G[0, 0] * x + G[0, 1] * y + G[0, 2] * z) / w, (G[1, 0] * x + G[1, 1] * y + G[1, 2] * z) / w, front


class _Pattern:
    """Reflectance of the printed face at board coordinates in square units (corner 0 at the origin)."""

    def __init__(self, board: BoardSpec, margin_squares: float) -> None:
        self.board = board
        # the printed pattern, [lo, hi) in square units on both axes, and its texture's scale and origin
        self.pattern_lo, self.pattern_hi = board.printed_bounds()
        self.pps, self.origin = float(CHARUCO_TEXTURE_PX_PER_SQUARE), -1.0
        self.texture: np.ndarray | None = None
        img = None
        if board.kind == CHARUCO:
            pps = CHARUCO_TEXTURE_PX_PER_SQUARE
            sx, sy = board.squares
            img = make_charuco_board(board).generateImage((sx * pps, sy * pps), marginSize=0, borderBits=1)
            if board.inverted:  # printed as a negative: white markers on black squares
                img = 255 - img
        elif board.kind == APRILGRID:
            img = aprilgrid_texture(board)
            self.pps, self.origin = float(APRILGRID_TEXTURE_PX_PER_TAG), -float(board.tag_spacing or 0.0)
        self.lo_x, self.lo_y = self.pattern_lo[0] - margin_squares, self.pattern_lo[1] - margin_squares
        self.hi_x, self.hi_y = self.pattern_hi[0] + margin_squares, self.pattern_hi[1] + margin_squares
        if img is not None:
            self.texture = (
                BLACK_REFLECTANCE + (WHITE_REFLECTANCE - BLACK_REFLECTANCE) * img.astype(np.float32) / 255.0
            )

    def inside(self, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        return (bx >= self.lo_x) & (bx < self.hi_x) & (by >= self.lo_y) & (by < self.hi_y)

    def value(self, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        """Reflectance inside the board outline (callers mask the outside)."""
        (lo_x, lo_y), (hi_x, hi_y) = self.pattern_lo, self.pattern_hi
        in_pattern = (bx >= lo_x) & (bx < hi_x) & (by >= lo_y) & (by < hi_y)
        if self.texture is None:
            black = (np.floor(bx) + np.floor(by)) % 2 == 0
            inner = np.where(black, BLACK_REFLECTANCE, WHITE_REFLECTANCE)
        else:
            pps, origin = self.pps, self.origin
            n, width = bx.size, 4096  # cv2.remap wants maps under 32767 rows: sample in 4096-wide rows
            pad = (-n) % width
            maps = [
                np.pad(((v.ravel() - origin) * pps - 0.5).clip(-2, 1e6).astype(np.float32), (0, pad)).reshape(
                    -1, width
                )
                for v in (bx, by)
            ]
            inner = (
                cv2.remap(self.texture, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                .ravel()[:n]
                .reshape(bx.shape)
            )
        return np.where(in_pattern, inner, WHITE_REFLECTANCE)

    def needs_supersampling(
        self, bx: np.ndarray, by: np.ndarray, foot_x: np.ndarray, foot_y: np.ndarray
    ) -> np.ndarray:
        """Pixels whose footprint may cross an edge of the pattern or of the outline."""
        near_outline = (
            (bx >= self.lo_x - foot_x)
            & (bx < self.hi_x + foot_x)
            & (by >= self.lo_y - foot_y)
            & (by < self.hi_y + foot_y)
        )
        if self.texture is not None:  # markers have edges everywhere: supersample the whole board
            return near_outline
        margin_edge = (np.abs(bx - np.round(bx - self.lo_x) - self.lo_x) < foot_x) | (
            np.abs(by - np.round(by - self.lo_y) - self.lo_y) < foot_y
        )
        grid_edge = (np.abs(bx - np.round(bx)) < foot_x) | (np.abs(by - np.round(by)) < foot_y)
        return near_outline & (grid_edge | margin_edge)


@dataclass(frozen=True)
class Photometry:
    """Illumination, optics and sensor of one shot. Intensities are on the 0..255 scale."""

    gain: float = 235.0
    illumination_slope: tuple[float, float] = (0.0, 0.0)
    blur_sigma_px: float = 0.7
    read_noise_dn: float = 1.0
    shot_noise_gain: float = 0.02

    @classmethod
    def random(cls, rng: np.random.Generator) -> Photometry:
        return cls(
            gain=float(rng.uniform(200.0, 245.0)),
            illumination_slope=(float(rng.uniform(-0.12, 0.12)), float(rng.uniform(-0.12, 0.12))),
            blur_sigma_px=float(rng.uniform(0.55, 0.85)),
        )


def _rook_offsets(supersample: int) -> tuple[np.ndarray, np.ndarray]:
    """n = supersample**2 sub-pixel offsets in (-0.5, 0.5), every one on its own row and column.

    A regular s x s grid resolves an axis-aligned edge to only s + 1 coverage levels (a 0.125 px
    corner bias at s = 4); this "n-rooks" pattern (sample k at column k and row k * step mod n, step
    coprime with n so every row is used once) resolves it to n + 1 levels: 1/72 px at s = 6.
    """
    n = supersample * supersample
    k = np.arange(n)
    step = next(a for a in range(int(np.sqrt(n)) + 1, n) if np.gcd(a, n) == 1)
    return (k + 0.5) / n - 0.5, ((k * step) % n + 0.5) / n - 0.5


def render_background(image_size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(H, W) float32 reflectance of a smooth, dull desk-and-wall background in 0.2..0.55."""
    width, height = image_size
    coarse = rng.uniform(0.2, 0.55, size=(6, 8)).astype(np.float32)
    return cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC).clip(0.15, 0.6)


class RayCamera(Protocol):
    """A lens that supplies its own per-pixel ray map, as ``padded_ray_map`` returns it (e.g.
    synth_fisheye.FisheyeCamera)."""

    @property
    def image_size(self) -> tuple[int, int]: ...

    def ray_map(self) -> tuple[np.ndarray, ...]: ...


class ProjectingCamera(Protocol):
    """A lens that projects board points itself (e.g. synth_fisheye.FisheyeCamera)."""

    def project(self, points_board_m: np.ndarray, T_cam_board: np.ndarray) -> np.ndarray: ...


def render_view(
    camera: PinholeCamera | RayCamera,
    board: BoardSpec,
    T_cam_board: np.ndarray,
    rng: np.random.Generator,
    photometry: Photometry | None = None,
    background: np.ndarray | None = None,
    supersample: int = 6,
    margin_squares: float = 1.0,
) -> np.ndarray:
    """Render one board photo.

    Args:
        T_cam_board: (4, 4) float64, metres.
        rng: seeded generator (sensor noise; background when ``background`` is None).
        background: (H, W) float reflectance in 0..1, or None for a random smooth one.

    Returns:
        (H, W) uint8 grey image.
    """
    photometry = photometry or Photometry()
    width, height = camera.image_size
    rays = camera.ray_map() if not isinstance(camera, PinholeCamera) else _ray_map(camera.key())
    x, y, z, x_u, x_v, y_u, y_v, z_u, z_v, valid = rays
    R, t = np.asarray(T_cam_board, np.float64)[:3, :3], np.asarray(T_cam_board, np.float64)[:3, 3]
    plane = np.column_stack([R[:, 0], R[:, 1], t])
    # board metres -> square units on the way out of the inverse plane map
    G = np.diag([1.0 / board.square_size_m, 1.0 / board.square_size_m, 1.0]) @ np.linalg.inv(plane)
    pattern = _Pattern(board, margin_squares)
    bg = render_background(camera.image_size, rng) if background is None else background.astype(np.float32)

    bx, by, front = _board_coords(G, x, y, z)
    hit = front & valid & pattern.inside(bx, by)
    refl = np.where(hit, pattern.value(bx, by), bg).astype(np.float32)

    # local footprint of one pixel in board square units (half-width plus the sub-sample spread)
    gx_u, gx_v = np.gradient(bx, axis=1), np.gradient(bx, axis=0)
    gy_u, gy_v = np.gradient(by, axis=1), np.gradient(by, axis=0)
    foot_x = 0.75 * (np.abs(gx_u) + np.abs(gx_v))
    foot_y = 0.75 * (np.abs(gy_u) + np.abs(gy_v))
    todo = front & valid & pattern.needs_supersampling(bx, by, foot_x, foot_y)
    rows, cols = np.nonzero(todo)
    if rows.size:
        ou, ov = _rook_offsets(supersample)
        sx = x[rows, cols][:, None] + x_u[rows, cols][:, None] * ou + x_v[rows, cols][:, None] * ov
        sy = y[rows, cols][:, None] + y_u[rows, cols][:, None] * ou + y_v[rows, cols][:, None] * ov
        sz = z[rows, cols][:, None] + z_u[rows, cols][:, None] * ou + z_v[rows, cols][:, None] * ov
        sbx, sby, sfront = _board_coords(G, sx, sy, sz)
        shit = sfront & pattern.inside(sbx, sby)
        svalue = np.where(shit, pattern.value(sbx, sby), bg[rows, cols][:, None])
        refl[rows, cols] = svalue.mean(axis=1)

    # illumination: a gentle gradient across the image and Lambert falloff with the board's tilt
    ramp_u = np.linspace(-0.5, 0.5, width, dtype=np.float32)[None, :]
    ramp_v = np.linspace(-0.5, 0.5, height, dtype=np.float32)[:, None]
    light = 1.0 + photometry.illumination_slope[0] * ramp_u + photometry.illumination_slope[1] * ramp_v
    lambert = np.float32(0.8 + 0.2 * abs(R[2, 2]))
    radiance = (photometry.gain * refl * np.where(hit, lambert, np.float32(1.0)) * light).astype(np.float32)
    if photometry.blur_sigma_px > 0:
        radiance = np.asarray(cv2.GaussianBlur(radiance, (0, 0), photometry.blur_sigma_px), np.float32)
    sigma = np.sqrt(photometry.read_noise_dn**2 + photometry.shot_noise_gain * np.maximum(radiance, 0))
    noisy = radiance + sigma * rng.standard_normal(radiance.shape).astype(np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def true_corners_px(
    camera: PinholeCamera | ProjectingCamera, board: BoardSpec, T_cam_board: np.ndarray
) -> np.ndarray:
    """(cols * rows, 2) float64 true inner-corner pixels, row-major ids."""
    return camera.project(board.object_points(), T_cam_board)
