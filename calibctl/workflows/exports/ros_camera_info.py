"""ROS camera_info YAML: what calibctl writes, and what ROS itself would refuse to load.

The rules follow ROS's own reader (image_common, camera_calibration_parsers ``parse_yml.cpp``,
``readCalibrationYml``): ``image_width``, ``image_height``, ``camera_matrix`` (3x3),
``rectification_matrix`` (3x3), ``projection_matrix`` (3x4) and ``distortion_coefficients`` are read
unconditionally, each matrix as ``rows``/``cols``/``data`` with ``rows*cols`` numbers; a missing
``camera_name`` becomes "unknown" and a missing ``distortion_model`` is assumed plumb_bob with a
warning. image_geometry knows three distortion models: plumb_bob (k1 k2 p1 p2 k3), rational_polynomial
(k1 k2 p1 p2 k3 k4 k5 k6) and equidistant (fisheye k1..k4). camera_info_manager accepts camera names of
``[A-Za-z0-9_]`` only and warns on every load otherwise.
"""

from __future__ import annotations

import re
from typing import Any

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.lint import Finding
from calibctl.errors import InputError, UsageError

MATRICES: dict[str, tuple[int, int] | None] = {
    "camera_matrix": (3, 3),
    "distortion_coefficients": None,  # 1 x N, N set by the distortion model
    "rectification_matrix": (3, 3),
    "projection_matrix": (3, 4),
}
DISTORTION_COEFFICIENTS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}
CAMERA_NAME = re.compile(r"^[A-Za-z0-9_]+$")
_REFUSED_FIX = "export it again with `calibctl export SERIAL --format ros`, or fix the named field"


def camera_name_for(serial: str, requested: str | None = None) -> str:
    """``requested`` if camera_info_manager accepts it, else the serial with other characters as '_'."""
    if requested is None:
        return re.sub(r"[^A-Za-z0-9_]", "_", serial)
    if not CAMERA_NAME.match(requested):
        raise UsageError(
            f"--camera-name '{requested}' is not a valid ROS camera name",
            "camera_info_manager accepts letters, digits and '_' only (e.g. front_left)",
        )
    return requested


def distortion_for(dist_coeffs: list[float], model_name: str | None = None) -> tuple[str, list[float]]:
    """ROS names: the fisheye model -> equidistant (D = k1..k4); otherwise 5 coefficients -> plumb_bob,
    8 -> rational_polynomial (4 are k1 k2 p1 p2, padded with k3 = 0)."""
    if model_name == "fisheye":
        if len(dist_coeffs) != DISTORTION_COEFFICIENTS["equidistant"]:
            raise InputError(
                f"a fisheye calibration has 4 coefficients (k1..k4), this one has {len(dist_coeffs)}",
                "export as json instead",
            )
        return "equidistant", list(dist_coeffs)
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


def camera_info(art: CalibrationArtifact, camera_name: str | None = None) -> dict[str, Any]:
    """The camera_info document for ``art``, in the key order ROS's writer uses."""
    k = art.camera_matrix
    model, dist = distortion_for(art.dist_coeffs, art.model.name)
    return {
        "image_width": art.image_size[0],
        "image_height": art.image_size[1],
        "camera_name": camera_name_for(art.serial, camera_name),
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


_ROS_KEYS = {"image_width", "image_height", "camera_name", "distortion_model", *MATRICES}


def looks_like_camera_info(data: Any) -> bool:
    """Two or more camera_info keys: a camera_info file (perhaps one ROS would refuse), not another
    document."""
    return isinstance(data, dict) and len(_ROS_KEYS & set(data)) >= 2


def _refused(message: str) -> Finding:
    return Finding(
        rule="ros-camera-info",
        severity="error",
        message=f"ROS would refuse this file: {message}",
        fix=_REFUSED_FIX,
    )


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _matrix_problem(data: dict[str, Any], name: str, shape: tuple[int, int] | None) -> str | None:
    node = data.get(name)
    if not isinstance(node, dict):
        return (
            f"{name} is missing (it needs rows, cols and data)"
            if node is None
            else f"{name} is not a rows/cols/data map"
        )
    rows, cols, values = node.get("rows"), node.get("cols"), node.get("data")
    if (
        not (isinstance(rows, int) and isinstance(cols, int))
        or isinstance(rows, bool)
        or isinstance(cols, bool)
    ):
        return f"{name} needs integer rows and cols"
    if shape is not None and (rows, cols) != shape:
        return f"{name} is {rows}x{cols}, ROS reads it as {shape[0]}x{shape[1]}"
    if not isinstance(values, list) or not all(_is_number(v) for v in values):
        return f"{name}.data is not a list of numbers"
    if len(values) != rows * cols:
        return f"{name} says {rows}x{cols} but has {len(values)} numbers"
    return None


def check_camera_info(data: dict[str, Any]) -> list[Finding]:
    """Every reason ROS would refuse or misread ``data`` (errors) or warn about it (warnings)."""
    refused = [
        _refused(f"{key} is missing or not a positive integer")
        for key in ("image_width", "image_height")
        if not (isinstance(data.get(key), int) and not isinstance(data.get(key), bool) and data[key] > 0)
    ]
    problems = {name: _matrix_problem(data, name, shape) for name, shape in MATRICES.items()}
    refused += [_refused(p) for p in problems.values() if p]
    model = data.get("distortion_model")
    findings: list[Finding] = []
    if model is None:
        findings.append(
            Finding(
                rule="ros-distortion-model",
                severity="warning",
                message="no distortion_model: ROS assumes plumb_bob and warns on every load",
                fix="add `distortion_model: plumb_bob` (or the model the coefficients belong to)",
            )
        )
        model = "plumb_bob"
    if model not in DISTORTION_COEFFICIENTS:
        refused.append(
            Finding(
                rule="ros-distortion-model",
                severity="error",
                message=f"distortion_model '{model}' is unknown to ROS image_geometry",
                fix=f"use one of {', '.join(DISTORTION_COEFFICIENTS)}",
            )
        )
    elif problems["distortion_coefficients"] is None:
        count, expected = len(data["distortion_coefficients"]["data"]), DISTORTION_COEFFICIENTS[model]
        if count != expected:
            refused.append(
                Finding(
                    rule="ros-distortion-model",
                    severity="error",
                    message=f"{model} takes {expected} distortion coefficients, the file has {count}",
                    fix="export again, or name the model the coefficients belong to",
                )
            )
    name = data.get("camera_name")
    if not (isinstance(name, str) and CAMERA_NAME.match(name)):
        shown = "missing (ROS uses 'unknown')" if name is None else f"'{name}'"
        findings.append(
            Finding(
                rule="ros-camera-name",
                severity="warning",
                message=f"camera_name {shown} is not valid for camera_info_manager ([A-Za-z0-9_])",
                fix="export with --camera-name NAME (letters, digits, '_')",
            )
        )
    return refused + findings
