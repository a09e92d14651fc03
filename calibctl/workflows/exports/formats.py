"""Export and read calibration files in the formats robots and tools use.

- ``json``/``yaml``: the full calibctl artifact (hash and status included; ``calibctl import`` reads it).
- ``ros``: the camera_info YAML that ROS camera_calibration_parsers reads (see ``ros_camera_info``).
- ``kalibr``: a one-camera Kalibr camchain; ``mrcal``: an mrcal .cameramodel (pinhole models only).
- ``opencv``: a cv2.FileStorage YAML (camera_matrix, distortion_coefficients, image_width/height,
  status), written and read back by OpenCV itself. A fisheye calibration adds
  ``distortion_model: equidistant``: its distortion_coefficients are cv2.fisheye's k1..k4 (pass them to
  cv2.fisheye.*, not to cv2.undistort).

ROS, OpenCV, Kalibr and mrcal exports start with the trace header (``trace_header``): the version, its
status, the evidence lint needs, the artifact's store signature (when its store had a key: ``calibctl lint
--require-signature`` checks it against the version's content hash) and a hash of the file.
``load_calibration`` reads any of the four back.
"""

from __future__ import annotations

import json
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from calibctl import bounded
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.errors import InputError

if TYPE_CHECKING:  # the stamped formats' modules: a JSON export (the default) prints without them
    from calibctl.workflows.exports import trace_header

ExportFormat = Literal["json", "yaml", "ros", "opencv", "kalibr", "mrcal"]
EXPORT_FORMATS: tuple[str, ...] = ("json", "yaml", "ros", "opencv", "kalibr", "mrcal")
# the formats that carry the trace header (json and yaml are the artifact itself, with its content hash)
HEADER_FORMATS: tuple[str, ...] = ("ros", "opencv", "kalibr", "mrcal")
FileKind = Literal["calibctl", "ros", "opencv"]


def looks_like_artifact(data: Any) -> bool:
    """A parsed JSON/YAML document that claims to be a calibctl artifact (before schema validation)."""
    return isinstance(data, dict) and "camera_matrix" in data and "content_sha256" in data


def _opencv_text(art: CalibrationArtifact) -> str:
    import cv2
    import numpy as np

    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "calibration.yaml")
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
        fs.write("serial", art.serial)
        fs.write("version", art.version)
        fs.write("status", art.status)
        fs.write("image_width", art.image_size[0])
        fs.write("image_height", art.image_size[1])
        fs.write("camera_matrix", np.array(art.camera_matrix, dtype=np.float64))
        fs.write("distortion_coefficients", np.array([art.dist_coeffs], dtype=np.float64))
        if art.model.name == "fisheye":
            fs.write("distortion_model", "equidistant")
        fs.write("rms_px", art.rms_px)
        fs.write("content_sha256", art.content_sha256)
        fs.release()
        return Path(path).read_text(encoding="utf-8")


def _one_camera_text(art: CalibrationArtifact, fmt: str, topic: str | None = None) -> str:
    """A one-camera Kalibr camchain (cam0, no overlaps, topic ``topic``, default /<frame base>/image_raw) or
    mrcal .cameramodel
    (the camera is its own reference). mrcal has no Kannala-Brandt model: a fisheye is refused."""
    import numpy as np

    from calibctl.core.extrinsics.rig_problem import MemberIntrinsics
    from calibctl.core.extrinsics.rig_tree import RigTree
    from calibctl.workflows.exports import mrcal_model, rig_exports

    member = MemberIntrinsics(
        art.serial,
        np.array(art.camera_matrix, dtype=np.float64),
        np.array(art.dist_coeffs, dtype=np.float64),
        art.image_size,
        lens="fisheye" if art.model.name == "fisheye" else "pinhole",
    )
    if fmt == "kalibr":
        topics = {art.serial: topic} if topic else None
        return rig_exports.kalibr_camchain([member], RigTree(art.serial, ()), topics=topics)
    model = mrcal_model.cameramodel(
        member, np.eye(4), f"calibctl {art.ref} {art.status}", art.observed_region_px
    )
    if model is None:
        raise InputError(
            f"{art.ref}: {mrcal_model.missing_reason(member)}", "export it as opencv or ros instead"
        )
    return model


def _yaml_text(data: Any, **style: Any) -> str:
    import yaml  # only the yaml and ros formats write YAML: a JSON export or a lint never imports it

    return yaml.safe_dump(data, sort_keys=False, **style)


def render(
    art: CalibrationArtifact, fmt: str, *, camera_name: str | None = None, topic: str | None = None
) -> str:
    """The artifact as text in ``fmt``; ``camera_name`` is the ROS camera name (default: from the serial),
    ``topic`` Kalibr's rostopic (default: /<frame base>/image_raw)."""
    document = art.model_dump(mode="json", exclude={"signature"} if art.signature is None else None)
    if fmt == "json":
        return json.dumps(document, indent=2, allow_nan=False) + "\n"
    if fmt == "yaml":
        return _yaml_text(document)
    from calibctl.workflows.exports import ros_camera_info, trace_header

    if fmt == "ros":
        info = ros_camera_info.camera_info(art, camera_name)
        return trace_header.stamp(art, _yaml_text(info, default_flow_style=None), signed=True)
    if fmt == "opencv":
        return trace_header.stamp(art, _opencv_text(art), signed=True)
    if fmt in ("kalibr", "mrcal"):
        return trace_header.stamp(art, _one_camera_text(art, fmt, topic), signed=True)
    raise InputError(f"unknown export format '{fmt}'", f"choose one of {', '.join(EXPORT_FORMATS)}")


@dataclass(frozen=True)
class CalibrationFile:
    """A calibration file as read back: its kind, its content as plain data, and its trace header."""

    source: str
    kind: FileKind
    data: dict[str, Any]
    header: trace_header.TraceHeader | None
    rig_header: trace_header.RigTraceHeader | None = None  # a camera's file of a rig export


_OPENCV_XML = re.compile(r"^\s*(<\?xml[^>]*\?>\s*)?(<!--.*?-->\s*)*<opencv_storage>", re.DOTALL)
_OPENCV_JSON_MATRIX = re.compile(r'"type_id"\s*:\s*"opencv-matrix"')


def _is_opencv(text: str) -> bool:
    """An OpenCV FileStorage by its content: YAML's ``%YAML:`` directive (or ``%YAML`` with an
    !!opencv-matrix), XML's ``<opencv_storage>`` root, or JSON with an ``"type_id": "opencv-matrix"`` node."""
    if text.startswith("%YAML:") or (text.startswith("%YAML") and "!!opencv-matrix" in text):
        return True
    if _OPENCV_XML.match(text):
        return True
    return text.lstrip().startswith("{") and bool(_OPENCV_JSON_MATRIX.search(text))


def opencv_data(text: str, source: str) -> dict[str, Any]:
    """Every top-level number, string and matrix OpenCV reads from ``text`` (matrices as nested lists)."""
    import cv2

    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as exc:  # a parse error can surface as SystemError from the binding
        cause = exc.__cause__ or exc
        lines = [line for line in str(cause).strip().splitlines() if line.strip()]
        raise InputError(
            f"{source}: OpenCV cannot read this FileStorage file ({lines[-1] if lines else 'parse error'})",
            "export it again with `calibctl export SERIAL --format opencv`",
        ) from exc
    data: dict[str, Any] = {}
    try:
        for key in fs.root().keys():  # noqa: SIM118 - a cv2.FileNode, not a dict
            node = fs.getNode(key)
            if node.isString():
                data[key] = node.string()
            elif node.isInt():
                data[key] = int(node.real())
            elif node.isReal():
                data[key] = node.real()
            elif node.isMap() and "dt" in node.keys():  # an !!opencv-matrix  # noqa: SIM118
                try:
                    data[key] = node.mat().tolist()
                except cv2.error as exc:
                    raise InputError(
                        f"{source}: {key} is not a matrix OpenCV can read (rows x cols, dt, data)",
                        "export it again with `calibctl export SERIAL --format opencv`",
                    ) from exc
    finally:
        fs.release()
    return data


def load_structured_file(path: Path) -> Any:
    """Read JSON or YAML through the one bounded loader; unreadable, malformed or hostile input is an
    error naming the file."""
    return bounded.load_file(path)


def load_calibration(path: Path) -> CalibrationFile:
    """Read a calibctl artifact (JSON/YAML), a ROS camera_info or an OpenCV FileStorage export."""
    text = bounded.read_text(path)
    return calibration_from_text(text, str(path), path.suffix.lower() == ".json")


def calibration_from_text(text: str, source: str, is_json: bool = False) -> CalibrationFile:
    """``load_calibration`` on text already read (``source`` names it in messages)."""
    from calibctl.workflows.exports import ros_camera_info, trace_header

    header, rig_header = trace_header.read(text), trace_header.read_rig(text)
    if _is_opencv(text):
        return CalibrationFile(
            source, "opencv", bounded.check_tree(opencv_data(text, source), source), header, rig_header
        )
    data = bounded.parse_json(text, source) if is_json else bounded.parse_yaml(text, source)
    if looks_like_artifact(data):
        return CalibrationFile(source, "calibctl", data, header)
    if ros_camera_info.looks_like_camera_info(data):
        return CalibrationFile(source, "ros", data, header, rig_header)
    raise InputError(
        f"{source} is not a calibration: lint looked for a calibctl artifact (camera_matrix + "
        "content_sha256), "
        "ROS camera_info (image_width, camera_matrix, ...), OpenCV FileStorage (%YAML:1.0, <opencv_storage>, "
        "or JSON with opencv-matrix nodes) and the rig exports (bundle manifest.json, rig or hand-eye JSON, "
        "tf_static, URDF, Kalibr camchain, OpenCV stereo)",
        "lint takes files written by `calibctl export` / `calibctl rig export` or ROS camera_calibration",
    )
