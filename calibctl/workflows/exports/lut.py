"""Undistortion and rectification look-up tables: the maps a robot hands to ``cv2.remap`` every frame, as a
derived, versioned export of one calibration (``calibctl export SERIAL --format lut -o DIR``) or of each
stereo pair of a rig version (``calibctl rig export RIG --format lut -o DIR``).

The folder holds ``lut.yaml``, the source's own document (``calibration.json``: the artifact as ``export
--format json`` writes it; ``rig.json``: the rig version) and, per camera, four ``.npy`` maps
(core.intrinsics.undistort_maps): OpenCV's fixed-point pair (``NAME.map1_16sc2.npy`` int16 (h, w, 2) +
``NAME.map2_16uc1.npy`` uint16 (h, w)) and the float pair (``NAME.map_x_32f.npy``, ``NAME.map_y_32f.npy``,
float32 (h, w)). ``.npy`` because it is the raw array behind a 128-byte header: ``np.load`` (or a memory map)
reads it in the time it takes to read the bytes, C++ reads it with cnpy or by skipping the header, and each
map has its own sha256; an OpenCV FileStorage .yml.gz holds the numbers as text (a 1280x960 float pair: 2.7 s
to read against 18 ms for the two .npy files, docs/exports.md).

``lut.yaml`` starts with the trace header of its source (trace_header: a camera's ``calibctl SERIAL@V STATUS
sha256 S`` and its ``calibctl signature`` line, or a rig's ``calibctl rig RIG@V ...``, ``rig-signature`` and
``member`` lines; then ``file-sha256``), and lists per camera what OpenCV needs to build the maps again:
the source K and distortion, the image size, R, the output projection P (its left 3x3 is the undistorted
image's K), alpha (pinhole) or balance (fisheye), and each map file's type, shape, bytes and sha256.
``calibctl lint DIR`` checks every file, checks those numbers against the source document (whose content
hash is the one the signature covers), derives the maps again from them, and with ``--db`` refuses
a LUT whose source is not the active version (a stale LUT: seed chapter 1's "apply it to a different
stream").
"""

from __future__ import annotations

import hashlib
import io
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from calibctl import __version__
from calibctl.workflows.exports import bundle

if TYPE_CHECKING:  # cv2: built when maps are, not when lint recognises a LUT header
    from calibctl.artifacts.rig import RigCalibration
    from calibctl.core.extrinsics.rig_problem import MemberIntrinsics
    from calibctl.core.extrinsics.rig_tree import RigTree
    from calibctl.core.intrinsics import undistort_maps

LUT_FORMAT = "calibctl-undistortion-lut"
LUT_SCHEMA_VERSION = 1
HEADER = "lut.yaml"
CAMERA_DOCUMENT = "calibration.json"  # the source artifact as `calibctl export --format json` writes it
RIG_DOCUMENT = "rig.json"  # the source rig version as `calibctl rig export --format json` writes it
_FORMAT_LINE = re.compile(rf"^format: {LUT_FORMAT}\s*$", re.MULTILINE)


def looks_like_lut(text: str) -> bool:
    """A LUT header by its content (any file name)."""
    return bool(_FORMAT_LINE.search(text))


def is_lut_folder(path: Path) -> bool:
    try:
        return looks_like_lut((path / HEADER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False


@dataclass(frozen=True)
class LutCamera:
    """One camera's maps to build: its source numbers and the output R and P.

    ``name`` is the file stem (``cam0``, or ``stereo_cam0_cam1.cam0`` in a pair); ``free`` is alpha for a
    pinhole lens and balance for a fisheye (None for a rectified pair: cv2.stereoRectify's alpha -1)."""

    serial: str
    version: int
    content_sha256: str
    name: str
    lens: undistort_maps.Lens
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    R: np.ndarray
    P: np.ndarray
    free: float | None = None
    pair: tuple[str, str] | None = None  # (left serial, right serial) of a rectified pair
    frame: str | None = None
    T_right_left: np.ndarray | None = None  # (4, 4) the pair's pose cv2.stereoRectify took (m)


def single_camera(
    serial: str,
    version: int,
    content_sha256: str,
    name: str,
    lens: undistort_maps.Lens,
    camera_matrix: Any,
    dist_coeffs: Any,
    image_size: tuple[int, int],
    free: float,
) -> LutCamera:
    """A camera undistorted on its own: R = I, P = [K' | 0] with K' from alpha / balance ``free``."""
    from calibctl.core.intrinsics import undistort_maps

    K, D = np.asarray(camera_matrix, dtype=np.float64), np.asarray(dist_coeffs, dtype=np.float64)
    new_K = undistort_maps.output_camera(K, D, image_size, lens, free)
    P = np.hstack([new_K, np.zeros((3, 1))])
    return LutCamera(serial, version, content_sha256, name, lens, K, D, image_size, np.eye(3), P, free)


def rig_cameras(
    cal: RigCalibration,
    members: list[MemberIntrinsics],
    cameras: RigTree,
    stem: Callable[[str, str, str], str],
    frame: Callable[[str], str | None],
) -> list[LutCamera]:
    """Per camera edge of the rig (the bundle's stereo pairs), both cameras with the pair's rectification:
    R1/P1 and R2/P2 of the pair's stereo file (core.extrinsics.rig_metrics.rectify) on T_right_left.
    ``stem(left, right, serial)`` names the files, ``frame(serial)`` the robot frame."""
    from calibctl.core.extrinsics.rig_metrics import rectify

    by_name = {m.name: m for m in members}
    by_serial = {m.serial: m for m in cal.members}
    out = []
    for e in cameras.edges:
        T_right_left = cameras.T(e.child, e.parent)
        rect = rectify(by_name[e.parent], by_name[e.child], T_right_left)
        for serial, R, P in ((e.parent, rect.R1, rect.P1), (e.child, rect.R2, rect.P2)):
            m = by_name[serial]
            out.append(
                LutCamera(
                    serial,
                    by_serial[serial].version,
                    by_serial[serial].content_sha256,
                    stem(e.parent, e.child, serial),
                    "fisheye" if m.lens == "fisheye" else "pinhole",
                    m.camera_matrix,
                    m.dist_coeffs,
                    m.image_size,
                    R,
                    P,
                    pair=(e.parent, e.child),
                    frame=frame(serial),
                    T_right_left=T_right_left,
                )
            )
    return out


def source_of(kind: str, ref: str, status: str, content_sha256: str, document: bytes) -> dict[str, Any]:
    """lut.yaml's ``source``: the version the maps were built from and its document in the folder."""
    return {
        "kind": kind,
        "ref": ref,
        "status": status,
        "content_sha256": content_sha256,
        "document": RIG_DOCUMENT if kind == "rig" else CAMERA_DOCUMENT,
        "document_sha256": hashlib.sha256(document).hexdigest(),
    }


def npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()


def _matrix(a: np.ndarray) -> list[Any]:
    return np.asarray(a, dtype=np.float64).tolist()


def build(cameras: list[LutCamera]) -> tuple[dict[str, bytes], list[dict[str, Any]]]:
    """Every map file (name -> .npy bytes) and each camera's entry of lut.yaml."""
    from calibctl.core.intrinsics import undistort_maps

    payloads: dict[str, bytes] = {}
    entries = []
    for cam in cameras:
        maps = undistort_maps.maps(cam.camera_matrix, cam.dist_coeffs, cam.image_size, cam.lens, cam.R, cam.P)
        files = []
        for map_name, array in maps.items():
            path = f"{cam.name}.{map_name}.npy"
            payloads[path] = npy_bytes(array)
            type_name, dtype, _ = undistort_maps.MAP_TYPES[map_name]
            files.append(
                {
                    "map": map_name,
                    "path": path,
                    "type": type_name,
                    "dtype": dtype,
                    "shape": list(array.shape),
                    "bytes": len(payloads[path]),
                    "sha256": hashlib.sha256(payloads[path]).hexdigest(),
                }
            )
        free_key = "balance" if cam.lens == "fisheye" else "alpha"
        entries.append(
            {
                "serial": cam.serial,
                "version": cam.version,
                "content_sha256": cam.content_sha256,
                "name": cam.name,
                **({"frame_id": cam.frame} if cam.frame else {}),
                "lens": cam.lens,
                "image_size": [int(cam.image_size[0]), int(cam.image_size[1])],
                "camera_matrix": _matrix(cam.camera_matrix),
                "dist_coeffs": _matrix(np.ravel(cam.dist_coeffs)),
                "rectified_pair": list(cam.pair) if cam.pair else None,
                **({"T_right_left": _matrix(cam.T_right_left)} if cam.T_right_left is not None else {}),
                free_key: -1.0 if cam.free is None else float(cam.free),
                "R": _matrix(cam.R),
                "P": _matrix(cam.P),
                "maps": files,
            }
        )
    return payloads, entries


def header_body(source: Mapping[str, Any], entries: list[dict[str, Any]]) -> str:
    """lut.yaml below its trace header (the caller stamps it)."""
    import yaml

    doc = {
        "format": LUT_FORMAT,
        "schema_version": LUT_SCHEMA_VERSION,
        "calibctl_version": __version__,
        "source": dict(source),
        "remap": "cv2.remap(raw, map1, map2, cv2.INTER_LINEAR) or cv2.remap(raw, map_x, map_y, ...)",
        "cameras": entries,
    }
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)


def write_lut(out: Path, payloads: Mapping[str, bytes], header_text: str, *, force: bool) -> list[Path]:
    """The folder ``out``: the maps and lut.yaml, whole or not at all (--force replaces only a LUT folder)."""
    out = Path(out)
    bundle.check_target(out, force, "LUT", HEADER, is_lut_folder)
    return bundle.write_folder(out, {**payloads, HEADER: header_text.encode("utf-8")}, "LUT")
