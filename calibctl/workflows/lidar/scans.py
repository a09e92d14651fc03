"""LiDAR sweeps from files, bounded, and their pairing with images by frame number.

A sweep is a ``.pcd`` (PCD v0.7), a ``.npy`` (N x 3 or N x 4) or a whitespace text file (``.txt``,
``.xyz``, ``.asc``) of the same. Files are refused over ``CALIBCTL_MAX_INPUT_MB`` before reading. A
sweep whose median range is over ``MAX_MEDIAN_RANGE_M`` is in millimetres, not metres (no spinning
LiDAR in a calibration cell sees its surroundings 200 m away), and is refused naming the fix.

Pairing (the rig rule, core.extrinsics.rig_frames.frame_key): the last run of digits of the stem,
``pose7_full.pcd`` <-> ``pose7.png``. Two scans (or two images) with one number are an error (exit 2:
which one is meant cannot be guessed); a scan or image without a partner is reported ``not_paired``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibctl import bounded, files
from calibctl.core.capture.image_outcomes import list_images
from calibctl.core.extrinsics.rig_frames import frame_key
from calibctl.core.lidar.pcd import PointCloud, parse_array, parse_pcd
from calibctl.errors import InputError, UsageError

SCAN_SUFFIXES = (".pcd", ".npy", ".txt", ".xyz", ".asc")
MAX_MEDIAN_RANGE_M = 200.0


def read_scan(path: Path, scale_to_m: float = 1.0) -> PointCloud:
    """One sweep file -> PointCloud in metres (``scale_to_m``: 0.001 for a sweep written in mm)."""
    bounded.check_size(path, "read scan")
    with files.file_errors("read scan", path):
        data = Path(path).read_bytes()
    suffix = path.suffix.lower()
    if suffix == ".pcd":
        cloud = parse_pcd(data, str(path))
    else:
        cloud = parse_array(data, str(path), is_npy=suffix == ".npy")
    if scale_to_m != 1.0:
        cloud = PointCloud(
            cloud.points_m * scale_to_m, cloud.intensity, cloud.ring, cloud.time_s, cloud.dropped_nonfinite
        )
    if len(cloud.points_m):
        median = float(np.median(np.linalg.norm(cloud.points_m, axis=1)))
        if median > MAX_MEDIAN_RANGE_M:
            raise InputError(
                f"{path}: median range {median:.0f} m, the points look like millimetres "
                "(a board would measure ~1000x its size)",
                "give the scans in metres, or pass --scan-units mm",
            )
    return cloud


@dataclass(frozen=True)
class Pairing:
    """pairs: (frame number, image path, scan path) sorted by number; unpaired: (path, why)."""

    pairs: tuple[tuple[int, Path, Path], ...]
    unpaired: tuple[tuple[Path, str], ...]


def _by_key(paths: list[Path], what: str) -> tuple[dict[int, Path], list[tuple[Path, str]]]:
    out: dict[int, Path] = {}
    loose = []
    for p in paths:
        key = frame_key(p)
        if key is None:
            loose.append((p, f"no frame number in the {what}'s name"))
        elif key in out:
            raise InputError(
                f"two {what}s with frame number {key}: {out[key].name} and {p.name}",
                f"keep one {what} per frame number (the last number in the file name pairs "
                "images with scans)",
            )
        else:
            out[key] = p
    return out, loose


def pair(images_dir: Path, scans_dir: Path, pattern: str = "*") -> Pairing:
    """Pair the images of ``images_dir`` with the scans of ``scans_dir`` matching ``pattern`` (a glob, e.g.
    ``*_full.pcd``; module docstring)."""
    for d, what in ((images_dir, "--images"), (scans_dir, "--scans")):
        if not Path(d).is_dir():
            raise UsageError(f"{what} {d} is not a folder", "give the folder that holds the files")
    with files.file_errors("list", images_dir):
        images = list_images(images_dir)
    with files.file_errors("list", scans_dir):
        named = sorted(p for p in Path(scans_dir).glob(pattern) if p.suffix.lower() in SCAN_SUFFIXES)
    for p in named:
        kind = files.not_regular(p)
        if kind is not None:
            raise InputError(
                f"the scan {p} is {kind}, not a regular file",
                "put the sweep file itself there (or remove that entry), then solve again",
            )
    scans = named
    if not images:
        raise InputError(f"no images in {images_dir}", "give the folder of the camera's images of the board")
    if not scans:
        raise InputError(
            f"no scans ({', '.join(SCAN_SUFFIXES)}) matching {pattern!r} in {scans_dir}",
            "give the folder of the LiDAR sweeps (PCD or N x 3/4 arrays)",
        )
    img, loose_i = _by_key(images, "image")
    scn, loose_s = _by_key(scans, "scan")
    pairs = tuple((k, img[k], scn[k]) for k in sorted(set(img) & set(scn)))
    unpaired = [*loose_i, *loose_s]
    unpaired += [(img[k], "no scan with this frame number") for k in sorted(set(img) - set(scn))]
    unpaired += [(scn[k], "no image with this frame number") for k in sorted(set(scn) - set(img))]
    return Pairing(pairs, tuple(unpaired))
