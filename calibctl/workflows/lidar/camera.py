"""The camera's lens for the camera-LiDAR solve: a ROS camera_info file or a stored active calibration.

camera_info (the acfr set ships one): ``K`` (9), ``D``, ``width``, ``height``, ``distortion_model``
(``fisheye``/``equidistant``: k1..k4 of the equidistant model; ``plumb_bob``/``rational_polynomial``:
OpenCV's order). Read through the bounded loader like every outside file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibctl import bounded
from calibctl.config import Settings
from calibctl.errors import InputError, UsageError

_FISHEYE = {"fisheye", "equidistant", "kannala_brandt"}
_PINHOLE = {"plumb_bob": "k1k2p1p2k3", "rational_polynomial": "rational"}


@dataclass(frozen=True)
class Lens:
    """K (3, 3) px, distortion in ``model``'s order, image size (w, h), calibctl model name, where from."""

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    model: str
    source: str


def _numbers(data: dict, key: str, n: int | None, source: str) -> np.ndarray:
    value = data.get(key)
    if isinstance(value, dict):  # ROS 1 style: {rows, cols, data}
        value = value.get("data")
    try:
        arr = np.asarray(value, np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(
            f"{source}: {key} is not a list of numbers", "a camera_info file has K (9) and D"
        ) from None
    if (n is not None and arr.size != n) or not np.isfinite(arr).all():
        raise InputError(
            f"{source}: {key} holds {arr.size} values{'' if n is None else f' (need {n})'}"
            " or a non-finite one",
            "is this a camera_info file?",
        )
    return arr


def lens_from_camera_info(path: Path) -> Lens:
    """A ROS camera_info YAML -> Lens (module docstring)."""
    data = bounded.load_file(path, "read camera info")
    source = str(path)
    if not isinstance(data, dict):
        raise InputError(f"{source}: not a camera_info mapping", "is this a camera_info file?")
    name = str(data.get("distortion_model", "plumb_bob")).lower()
    K = _numbers(data, "K" if "K" in data else "camera_matrix", 9, source).reshape(3, 3)
    D = _numbers(data, "D" if "D" in data else "distortion_coefficients", None, source)
    if name in _FISHEYE:
        if D.size != 4:
            raise InputError(f"{source}: a fisheye camera_info needs 4 coefficients in D, got {D.size}")
        model = "fisheye"
    elif name in _PINHOLE:
        model = _PINHOLE[name]
    else:
        raise InputError(
            f"{source}: distortion_model {name!r} is not fisheye, plumb_bob or rational_polynomial"
        )
    try:
        size = (int(data["width"]), int(data["height"]))
    except (KeyError, TypeError, ValueError):
        raise InputError(
            f"{source}: no integer width and height", "a camera_info file names its image size"
        ) from None
    _check_camera_matrix(K, size, source)
    return Lens(K, D, size, model, source)


def _check_camera_matrix(K: np.ndarray, size: tuple[int, int], source: str) -> None:
    """K must be a pinhole camera matrix [fx 0 cx; 0 fy cy; 0 0 1] with positive focal lengths and the
    principal point in the image: an all-zero K is what a driver publishes for an uncalibrated camera."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    w, h = size
    if not (fx > 0 and fy > 0 and np.allclose(K[2], (0, 0, 1)) and 0 < cx < w and 0 < cy < h):
        raise InputError(
            f"{source}: K is no camera matrix (fx {fx:g}, fy {fy:g}, cx {cx:g}, cy {cy:g}, last row "
            f"{' '.join(f'{v:g}' for v in K[2])}; need fx, fy > 0, the principal point inside the {w}x{h} "
            "image and a last row 0 0 1): the camera is not calibrated",
            "calibrate the camera first and give its camera_info (`calibctl export SERIAL --format ros`), "
            "or --serial SERIAL for its active calibration",
        )


def lens_from_store(settings: Settings, serial: str, version: int | None = None) -> Lens:
    """The active calibration of ``serial`` (or ``version``; NotFoundError, exit 2, when there is none)."""
    from calibctl.workflows.store_admin.records import open_store

    with open_store(settings) as store:
        art = store.get_artifact(serial, version)
    return Lens(
        np.array(art.camera_matrix, np.float64),
        np.array(art.dist_coeffs, np.float64),
        (int(art.image_size[0]), int(art.image_size[1])),
        art.model.name,
        f"{art.ref}",
    )


def load_lens(settings: Settings, camera_info: Path | None, serial: str | None) -> Lens:
    if (camera_info is None) == (serial is None):
        raise UsageError(
            "give the camera as exactly one of --camera-info FILE or --serial SERIAL",
            "--serial uses the camera's active calibration in the store",
        )
    return (
        lens_from_camera_info(camera_info)
        if camera_info is not None
        else lens_from_store(settings, serial or "")
    )
