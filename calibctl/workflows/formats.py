"""Export and read calibration files in the formats robots and tools use.

- ``json``/``yaml``: the full calibctl artifact (hash included; ``calibctl import`` reads the JSON back).
- ``ros``: the camera_info YAML that ROS camera_calibration_parsers reads (plumb_bob or rational_polynomial).
- ``opencv``: a cv2.FileStorage YAML (camera_matrix, distortion_coefficients, image_width/height), written
  by OpenCV itself so cv2.FileStorage is guaranteed to read it.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Literal

import yaml

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.errors import AlreadyExistsError, InputError

ExportFormat = Literal["json", "yaml", "ros", "opencv"]
EXPORT_FORMATS: tuple[str, ...] = ("json", "yaml", "ros", "opencv")


def looks_like_artifact(data: Any) -> bool:
    """A parsed JSON/YAML document that claims to be a calibctl artifact (before schema validation)."""
    return isinstance(data, dict) and "camera_matrix" in data and "content_sha256" in data


def ros_distortion_model(dist_coeffs: list[float]) -> tuple[str, list[float]]:
    """ROS names: 5 coefficients -> plumb_bob, 8 -> rational_polynomial (4 are padded with k3 = 0)."""
    if len(dist_coeffs) == 4:
        return "plumb_bob", [*dist_coeffs, 0.0]
    if len(dist_coeffs) == 5:
        return "plumb_bob", list(dist_coeffs)
    if len(dist_coeffs) == 8:
        return "rational_polynomial", list(dist_coeffs)
    raise InputError(
        f"ROS camera_info has no distortion model for {len(dist_coeffs)} OpenCV coefficients",
        "export as json or opencv instead",
    )


def to_ros_camera_info(art: CalibrationArtifact) -> dict[str, Any]:
    k = art.camera_matrix
    model, dist = ros_distortion_model(art.dist_coeffs)
    return {
        "image_width": art.image_size[0],
        "image_height": art.image_size[1],
        "camera_name": art.serial,
        "camera_matrix": {"rows": 3, "cols": 3, "data": [v for row in k for v in row]},
        "distortion_model": model,
        "distortion_coefficients": {"rows": 1, "cols": len(dist), "data": dist},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]},
        "projection_matrix": {
            "rows": 3,
            "cols": 4,
            "data": [k[0][0], k[0][1], k[0][2], 0.0, 0.0, k[1][1], k[1][2], 0.0, 0.0, 0.0, 1.0, 0.0],
        },
    }


def _opencv_text(art: CalibrationArtifact) -> str:
    import cv2
    import numpy as np

    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "calibration.yaml")
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
        fs.write("serial", art.serial)
        fs.write("version", art.version)
        fs.write("image_width", art.image_size[0])
        fs.write("image_height", art.image_size[1])
        fs.write("camera_matrix", np.array(art.camera_matrix, dtype=np.float64))
        fs.write("distortion_coefficients", np.array([art.dist_coeffs], dtype=np.float64))
        fs.write("rms_px", art.rms_px)
        fs.write("content_sha256", art.content_sha256)
        fs.release()
        return Path(path).read_text(encoding="utf-8")


def render(art: CalibrationArtifact, fmt: str) -> str:
    """The artifact as text in ``fmt``."""
    if fmt == "json":
        return json.dumps(art.model_dump(mode="json"), indent=2, allow_nan=False) + "\n"
    if fmt == "yaml":
        return yaml.safe_dump(art.model_dump(mode="json"), sort_keys=False)
    if fmt == "ros":
        header = f"# calibctl {art.serial}@{art.version} sha256 {art.content_sha256}\n"
        return header + yaml.safe_dump(to_ros_camera_info(art), sort_keys=False, default_flow_style=None)
    if fmt == "opencv":
        return _opencv_text(art)
    raise InputError(f"unknown export format '{fmt}'", f"choose one of {', '.join(EXPORT_FORMATS)}")


def write_new_file(path: Path, text: str, *, force: bool) -> None:
    """Write atomically (temp file + rename); never overwrite without ``force``."""
    if path.exists() and not force:
        raise AlreadyExistsError(f"{path} exists", "pass --force to overwrite it")
    if not path.parent.exists():
        raise InputError(f"cannot write {path}: folder {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_structured_file(path: Path) -> Any:
    """Read JSON or YAML (safely); unreadable or malformed input is an InputError naming the file."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise InputError(f"{path}: no such file") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it ({exc})") from exc
    if path.suffix.lower() == ".json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"{path}: malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from exc
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1} column {mark.column + 1}" if mark else ""
        raise InputError(f"{path}: malformed YAML{where}: {getattr(exc, 'problem', exc)}") from exc
