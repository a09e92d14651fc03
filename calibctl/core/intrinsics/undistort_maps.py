"""Undistortion / rectification look-up tables: the maps ``cv2.remap`` reads every frame on the robot.

A robot never evaluates the lens polynomial per pixel at runtime; it precomputes, once, where each output
pixel samples the raw image (seed chapter 1: "a LUT eight times the size of the image"). Both of OpenCV's
map encodings are built, by OpenCV itself, from the same camera numbers:

- ``fixed``: CV_16SC2 (int16 x, y, the integer source pixel) + CV_16UC1 (uint16, the 1/32 px sub-pixel cell
  index into remap's interpolation table): 6 bytes per pixel, what ``cv2.remap`` runs fastest on;
- ``float``: two CV_32FC1 maps (float32 source x and y, px): 8 bytes per pixel, exact to float32.

``output_camera`` chooses the new camera matrix of a single camera: ``cv2.getOptimalNewCameraMatrix``
(``alpha`` 0 = every output pixel valid, 1 = every source pixel kept) for a pinhole lens,
``cv2.fisheye.estimateNewCameraMatrixForUndistortRectify`` (``balance``, same meaning) for a fisheye.
``maps`` is ``cv2.initUndistortRectifyMap`` / ``cv2.fisheye.initUndistortRectifyMap`` with R (the stereo
rectification, identity for one camera) and P; ``decode_fixed`` turns the fixed-point pair back into
source pixels (lint compares it with a float map it derives again).
"""

from __future__ import annotations

from typing import Literal

import cv2
import numpy as np

Lens = Literal["pinhole", "fisheye"]

# map name -> (OpenCV type name, numpy dtype, channels): the order the files are written and listed in
MAP_TYPES: dict[str, tuple[str, str, int]] = {
    "map1_16sc2": ("CV_16SC2", "int16", 2),
    "map2_16uc1": ("CV_16UC1", "uint16", 1),
    "map_x_32f": ("CV_32FC1", "float32", 1),
    "map_y_32f": ("CV_32FC1", "float32", 1),
}
FIXED_POINT_CELLS = 32  # cv2.INTER_TAB_SIZE: the fixed-point maps resolve 1/32 px


def _dist(lens: Lens, dist_coeffs: np.ndarray) -> np.ndarray:
    D = np.asarray(dist_coeffs, dtype=np.float64).reshape(-1)
    return D[:4].reshape(4, 1) if lens == "fisheye" else D


def output_camera(
    camera_matrix: np.ndarray, dist_coeffs: np.ndarray, image_size: tuple[int, int], lens: Lens, free: float
) -> np.ndarray:
    """(3, 3) the undistorted image's camera matrix at the same size: ``free`` is alpha (pinhole) or balance
    (fisheye), 0 (crop to valid pixels) to 1 (keep every source pixel)."""
    K = np.asarray(camera_matrix, dtype=np.float64)
    size = (int(image_size[0]), int(image_size[1]))
    if lens == "fisheye":
        return np.asarray(
            cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(
                K, _dist(lens, dist_coeffs), size, np.eye(3), balance=float(free)
            ),
            dtype=np.float64,
        )
    new, _ = cv2.getOptimalNewCameraMatrix(K, _dist(lens, dist_coeffs), size, float(free), size)
    return np.asarray(new, dtype=np.float64)


def maps(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    lens: Lens,
    R: np.ndarray,
    P: np.ndarray,
) -> dict[str, np.ndarray]:
    """The four maps of MAP_TYPES (each (h, w) or (h, w, 2)), as OpenCV's own initUndistortRectifyMap
    writes them for K, D, R and the new camera (or projection) matrix P."""
    K = np.asarray(camera_matrix, dtype=np.float64)
    D = _dist(lens, dist_coeffs)
    R, P = np.asarray(R, dtype=np.float64), np.asarray(P, dtype=np.float64)
    size = (int(image_size[0]), int(image_size[1]))
    init = cv2.fisheye.initUndistortRectifyMap if lens == "fisheye" else cv2.initUndistortRectifyMap
    map1, map2 = init(K, D, R, P, size, cv2.CV_16SC2)
    map_x, map_y = init(K, D, R, P, size, cv2.CV_32FC1)
    return {"map1_16sc2": map1, "map2_16uc1": map2, "map_x_32f": map_x, "map_y_32f": map_y}


def expected_shape(name: str, image_size: tuple[int, int]) -> tuple[int, ...]:
    w, h = int(image_size[0]), int(image_size[1])
    return (h, w, 2) if MAP_TYPES[name][2] == 2 else (h, w)


def decode_fixed(map1: np.ndarray, map2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The source pixel (x, y) each output pixel of a CV_16SC2 + CV_16UC1 pair samples (float64, px)."""
    cells = np.asarray(map2, dtype=np.int64) & (FIXED_POINT_CELLS * FIXED_POINT_CELLS - 1)
    x = map1[..., 0] + (cells % FIXED_POINT_CELLS) / FIXED_POINT_CELLS
    y = map1[..., 1] + (cells // FIXED_POINT_CELLS) / FIXED_POINT_CELLS
    return x.astype(np.float64), y.astype(np.float64)
