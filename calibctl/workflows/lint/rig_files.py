"""Lint of the files ``calibctl rig export`` writes, recognised by their content: the bundle manifest (every
listed file present and unchanged, each one linted), the rig and hand-eye JSON documents (schema, content
hash), tf_static, URDF (a robot or its joints), the Kalibr camchain, mrcal .cameramodel and the OpenCV stereo
FileStorage (parse, numbers, frames). Each checks the rig trace header first (an edited file is
``content-hash``).

``rig_file_kind`` says which of these a text is (None: not a rig export; ``lint.lint_file`` takes the
camera formats). Rules: ``frames`` (a frame or topic ROS would refuse, a tree that is not one),
``transform`` (a rotation that is not one, a value that is not finite), ``kalibr`` (what Kalibr's
ConfigReader needs: cam_overlaps on every camera, 4 intrinsics, known distortion), ``schema``,
``content-hash``, ``bundle``; the cameras of Kalibr and OpenCV stereo files get the camera rules on their
numbers (``lint_facts`` without evidence: the members' own rules are `calibctl lint --rig RIG`).
"""

from __future__ import annotations

import ast
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import ValidationError

from calibctl import bounded
from calibctl.artifacts.calibration import RecordSignature
from calibctl.artifacts.common import validation_message
from calibctl.artifacts.lint import Finding
from calibctl.config import LintThresholds, Settings
from calibctl.errors import InputError
from calibctl.signing import EDITED, TrustedKeys, is_mismatch
from calibctl.workflows.exports import bundle, formats, sealed_result, trace_header
from calibctl.workflows.exports.frame_names import ROS_NAME, FrameNames
from calibctl.workflows.lint import store_match
from calibctl.workflows.lint.lint import (
    CalibrationFacts,
    LintResult,
    file_facts,
    lint_facts,
    lint_file,
    signature_rule,
    trace_of,
    trace_rules,
    with_evidence,
)
from calibctl.workflows.store_admin import keys

if (
    TYPE_CHECKING
):  # the rig and hand-eye models are built when such a document is linted, not for a camera file
    from calibctl.artifacts.handeye import HandEyeResult
    from calibctl.artifacts.rig import RigCalibration

KALIBR_IMU_FIELDS = {
    "accelerometer_noise_density",
    "accelerometer_random_walk",
    "gyroscope_noise_density",
    "gyroscope_random_walk",
}
_KALIBR_DISTORTION = {"radtan": 4, "equidistant": 4, "fov": 1, "none": 0}
_KALIBR_TARGETS: dict[str, dict[str, type]] = {  # field -> the type Kalibr's reader insists on
    "aprilgrid": {"tagCols": int, "tagRows": int, "tagSize": float, "tagSpacing": float},
    "checkerboard": {
        "targetCols": int,
        "targetRows": int,
        "rowSpacingMeters": float,
        "colSpacingMeters": float,
    },
}
_FIX_FRAME = (
    "name the frame with `calibctl rig export ... --frame SERIAL=NAME` ([a-zA-Z][a-zA-Z0-9_]* segments)"
)


def _error(rule: str, message: str, fix: str, severity: str = "error") -> Finding:
    return Finding(rule=rule, severity=severity, message=message, fix=fix)


_MRCAL = re.compile(r"^\s*(#[^\n]*\n\s*)*\{\s*(#[^\n]*\n\s*)*'lensmodel'")


def _parse(text: str, source: str) -> Any:
    if _MRCAL.match(text):  # a .cameramodel: a Python literal (mrcal reads it with ast.literal_eval too)
        try:
            return {"mrcal": ast.literal_eval(text)}
        except (ValueError, SyntaxError, MemoryError, RecursionError) as exc:
            raise InputError(
                f"{source}: not a readable mrcal .cameramodel ({exc})", "export it again"
            ) from exc
    stripped = text.lstrip()
    if stripped.startswith("<"):
        body = (
            stripped
            if stripped.startswith(("<?xml", "<robot"))
            else f"<robot name='joints'>{stripped}</robot>"
        )
        try:
            return ET.fromstring(body.encode("utf-8"))
        except ET.ParseError as exc:
            raise InputError(f"{source}: not well-formed XML ({exc})", "export it again") from exc
    if stripped.startswith("%YAML"):
        return None  # OpenCV FileStorage: formats reads it
    return bounded.parse_json(text, source) if stripped.startswith("{") else bounded.parse_yaml(text, source)


def rig_file_kind(text: str, data: Any) -> str | None:
    """bundle | rig-json | handeye-json | lidar-result | imu-edge-json | imu-result | tf | urdf | kalibr |
    kalibr-imu | kalibr-target | mrcal | opencv-stereo, or None."""
    if isinstance(data, ET.Element):
        return "urdf" if data.tag == "robot" else None
    if text.startswith("%YAML"):
        return "opencv-stereo" if all(f"\n{k}:" in text for k in ("K1", "K2", "R", "T")) else None
    if not isinstance(data, dict):
        return None
    if bundle.is_manifest(data):
        return "bundle"
    if isinstance(data.get("mrcal"), dict):
        return "mrcal"
    if {"rig", "edges", "members", "content_sha256"} <= set(data):
        return "rig-json"
    if data.get("kind") == "handeye" and "content_sha256" in data:
        return "handeye-json"
    if data.get("kind") == sealed_result.LIDAR_RESULT or set(data) >= LIDAR_RESULT_FIELDS:
        return sealed_result.LIDAR_RESULT
    if data.get("kind") == "imu" and "parent_frame" in data:
        return "imu-edge-json"
    if data.get("kind") == sealed_result.IMU_RESULT or set(data) >= IMU_RESULT_FIELDS:
        return sealed_result.IMU_RESULT
    if isinstance(data.get("transforms"), list):
        return "tf"
    if set(data) >= KALIBR_IMU_FIELDS:
        return "kalibr-imu"
    if "target_type" in data:
        return "kalibr-target"
    if data and all(
        k.startswith("cam") and isinstance(v, dict) and "intrinsics" in v for k, v in data.items()
    ):
        return "kalibr"
    return None


def _finite_matrix(value: Any, shape: tuple[int, int], what: str) -> tuple[np.ndarray | None, list[Finding]]:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(shape)
    except (TypeError, ValueError):
        return None, [
            _error("transform", f"{what} is not a {shape[0]}x{shape[1]} matrix of numbers", "export it again")
        ]
    if not np.all(np.isfinite(arr)):
        return None, [_error("finite", f"{what} has NaN or infinite values", "export it again")]
    return arr, []


def _rotation(R: np.ndarray, what: str) -> list[Finding]:
    if np.max(np.abs(R @ R.T - np.eye(3))) > 1e-6 or abs(np.linalg.det(R) - 1.0) > 1e-6:
        return [_error("transform", f"{what} is not a rotation (R R^T != I or det != 1)", "export it again")]
    return []


LIDAR_RESULT_FIELDS = {"transform", "outcomes", "outcome_counts", "gates", "status"}
IMU_RESULT_FIELDS = {"recording", "camera", "noise", "gates", "estimate", "row_test"}
_RESULT_FIX = {
    kind: f"write it again: `calibctl {room} solve ... -o FILE` (with a signing key configured, signed)"
    for kind, room in ((sealed_result.LIDAR_RESULT, "lidar"), (sealed_result.IMU_RESULT, "imu"))
}


def _result_transform(data: dict[str, Any], kind: str, source: str) -> list[Finding]:
    """A sealed result's transform against its own identities: the inverse beside it, the translation
    (LiDAR: ``transform``; camera-IMU: ``estimate``, T_imu_cam as ``matrix`` beside Kalibr's T_cam_imu)."""
    if kind == sealed_result.LIDAR_RESULT:
        block, inverse_key, t_key = data.get("transform"), "T_cam_lidar", "translation_m"
    else:
        block, inverse_key, t_key = data.get("estimate"), "T_cam_imu", None
    if not isinstance(block, dict):
        return []
    name = "transform" if kind == sealed_result.LIDAR_RESULT else "estimate"
    T, bad = _finite_matrix(block.get("matrix"), (4, 4), f"{name}.matrix")
    inverse, bad_inverse = _finite_matrix(block.get(inverse_key), (4, 4), f"{name}.{inverse_key}")
    if T is None or inverse is None:
        return bad + bad_inverse
    findings = _rotation(T[:3, :3], f"{name}.matrix")
    t = np.asarray(block.get(t_key) if t_key else T[:3, 3], dtype=np.float64)
    if (
        np.max(np.abs(T @ inverse - np.eye(4))) > 1e-6
        or t.shape != (3,)
        or np.max(np.abs(t - T[:3, 3])) > 1e-6
    ):
        what = f"{inverse_key} and {t_key}" if t_key else inverse_key
        findings.append(_error("transform", f"{source}: {what} are not {name}.matrix's", _RESULT_FIX[kind]))
    return findings


def _sealed_result(data: dict[str, Any], source: str, trusted: TrustedKeys, kind: str) -> list[Finding]:
    """A store-free ``lidar solve -o`` or ``imu solve -o`` result: its content hash, its transform's own
    identities, its status and its signature (``exports.sealed_result``)."""
    recorded = data.get("content_sha256")
    if not isinstance(recorded, str):
        return [
            _error(
                "content-hash",
                f"{source} carries no content hash (written before results were sealed)",
                _RESULT_FIX[kind],
            )
        ]
    if recorded != sealed_result.content_sha256(data):
        return [
            _error(
                "content-hash", f"{source} was edited (its content hash does not match)", _RESULT_FIX[kind]
            )
        ]
    findings = _result_transform(data, kind, source)
    if data.get("status") != "accepted":
        findings.append(
            _error(
                "status",
                f"{source} is a {data.get('status')} result: no transform a robot may load",
                "capture again as its failed gate says",
            )
        )
    seal = data.get("signature")
    if not isinstance(seal, dict):
        return findings + [_error("signature", f"{source} is not signed", SIGNATURE_FIX)]
    problem = trusted.check(
        seal.get("key_id"),
        seal.get("value"),
        sealed_result.message(kind, recorded),
        seal.get("public_key"),
    )
    problem = f"{problem}: {EDITED}" if is_mismatch(problem) else problem
    return findings + ([] if problem is None else [_error("signature", f"{source} {problem}", SIGNATURE_FIX)])


def _frame(name: Any, what: str) -> list[Finding]:
    if isinstance(name, str) and ROS_NAME.match(name):
        return []
    return [_error("frames", f"{what} '{name}' is not a legal ROS name", _FIX_FRAME)]


def _tree(edges: list[tuple[str, str]]) -> list[Finding]:
    parents: dict[str, str] = {}
    for parent, child in edges:
        if child in parents:
            return [
                _error(
                    "frames",
                    f"{child} has two parents ({parents[child]} and {parent}): not a tree",
                    "export again",
                )
            ]
        parents[child] = parent
    roots = {p for p, _ in edges if p not in parents}
    if edges and len(roots) != 1:
        return [
            _error("frames", f"the frames form {len(roots)} trees or a loop, not one tree", "export again")
        ]
    return []


def _tf(data: dict[str, Any]) -> list[Finding]:
    findings: list[Finding] = []
    edges = []
    for i, tr in enumerate(data["transforms"]):
        parent = (tr.get("header") or {}).get("frame_id") if isinstance(tr, dict) else None
        child = tr.get("child_frame_id") if isinstance(tr, dict) else None
        findings += _frame(parent, f"transform {i} frame_id") + _frame(child, f"transform {i} child_frame_id")
        moved = (tr.get("transform") or {}) if isinstance(tr, dict) else {}
        t, q = moved.get("translation") or {}, moved.get("rotation") or {}
        values = [t.get(k) for k in "xyz"] + [q.get(k) for k in "xyzw"]
        numbers = [float(v) for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
        if len(numbers) != 7 or not all(math.isfinite(v) for v in numbers):
            findings.append(
                _error(
                    "finite",
                    f"transform {parent} -> {child} has a missing or non-finite number",
                    "export again",
                )
            )
        elif abs(math.sqrt(sum(v * v for v in numbers[3:])) - 1.0) > 1e-6:
            findings.append(
                _error(
                    "transform",
                    f"transform {parent} -> {child}: the quaternion is not unit length",
                    "export again",
                )
            )
        edges.append((str(parent), str(child)))
    return findings + _tree(edges)


def _urdf(robot: ET.Element) -> list[Finding]:
    links = [link.get("name") for link in robot.findall("link")]
    findings = [f for name in links for f in _frame(name, "link")]
    edges = []
    for joint in robot.findall("joint"):
        parent, child = (joint.find(k) for k in ("parent", "child"))
        p, c = (None if e is None else e.get("link") for e in (parent, child))
        if links and (p not in links or c not in links):
            findings.append(
                _error(
                    "frames",
                    f"joint {joint.get('name')} joins {p} -> {c}, not two declared links",
                    "export again",
                )
            )
        origin = joint.find("origin")
        for attr in ("xyz", "rpy"):
            text = "0 0 0" if origin is None else origin.get(attr, "0 0 0")
            try:
                values = [float(v) for v in text.split()]
            except ValueError:
                values = []
            if len(values) != 3 or not all(math.isfinite(v) for v in values):
                findings.append(
                    _error(
                        "finite",
                        f"joint {joint.get('name')} origin {attr}='{text}' is not 3 finite numbers",
                        "export again",
                    )
                )
        edges.append((str(p), str(c)))
    return findings + _tree(edges)


@dataclass(frozen=True)
class Trace:
    """What vouches for a file's cameras (``lint.lint_facts``' trace) and the evidence of a camera header."""

    kind: str
    evidence: dict[str, Any]

    def lint(self, facts: CalibrationFacts, limits: LintThresholds) -> list[Finding]:
        return lint_facts(with_evidence(facts, self.evidence), limits, self.kind)


def _camera_facts(
    source: str, K: np.ndarray, dist: list[float], size: Any, equidistant: bool
) -> CalibrationFacts:
    ok = isinstance(size, list | tuple) and len(size) == 2 and all(isinstance(v, int) for v in size)
    return CalibrationFacts(
        source=source,
        kind="rig",
        image_size=(int(size[0]), int(size[1])) if ok else None,
        camera_matrix=K,
        dist_coeffs=np.asarray(dist, dtype=np.float64),
        distortion_model="equidistant" if equidistant else "brown-conrady",
    )


def _kalibr(data: dict[str, Any], source: str, limits: LintThresholds, trace: Trace) -> list[Finding]:
    findings: list[Finding] = []
    fix = "export it again with `calibctl rig export RIG --format kalibr`"
    for name, cam in data.items():
        intr, model, dist = (
            cam.get("intrinsics"),
            cam.get("distortion_model"),
            cam.get("distortion_coeffs") or [],
        )
        if "cam_overlaps" not in cam:
            findings.append(
                _error("kalibr", f"{name} has no cam_overlaps: Kalibr's getCamOverlaps fails", fix)
            )
        if model not in _KALIBR_DISTORTION or len(dist) != _KALIBR_DISTORTION.get(model, -1):
            findings.append(
                _error(
                    "kalibr",
                    f"{name}: distortion_model {model} with {len(dist)} coefficients is not "
                    "a Kalibr model (radtan 4, equidistant 4, fov 1, none 0)",
                    fix,
                )
            )
        if not (isinstance(intr, list) and len(intr) == 4):
            findings.append(_error("kalibr", f"{name}: intrinsics must be [fu, fv, pu, pv]", fix))
            continue
        if cam.get("rostopic") is not None and not ROS_NAME.match(str(cam["rostopic"]).lstrip("/")):
            findings.append(
                _error("frames", f"{name}: rostopic '{cam['rostopic']}' is not a legal ROS topic", _FIX_FRAME)
            )
        shift = cam.get("timeshift_cam_imu", 0.0)
        if isinstance(shift, bool) or not isinstance(shift, int | float) or not np.isfinite(shift):
            findings.append(_error("kalibr", f"{name}: timeshift_cam_imu {shift!r} is not a number (s)", fix))
        for key in ("T_cn_cnm1", "T_cam_imu"):
            if key in cam:
                T, bad = _finite_matrix(cam[key], (4, 4), f"{name}.{key}")
                findings += bad + ([] if T is None else _rotation(T[:3, :3], f"{name}.{key}"))
        K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1]], dtype=np.float64)
        facts = _camera_facts(
            f"{source}:{name}",
            K,
            dist if model == "equidistant" else [*dist, 0.0][:5],
            cam.get("resolution"),
            model == "equidistant",
        )
        findings += [
            f.model_copy(update={"message": f"{name}: {f.message}"}) for f in trace.lint(facts, limits)
        ]
    return findings


def _kalibr_imu(data: dict[str, Any]) -> list[Finding]:
    """Kalibr's imu.yaml: every noise field a positive finite number (Kalibr divides by them); with
    ``model: scale-misalignment`` its matrices 3x3 and finite, C_gyro_i a rotation."""
    fix = "export it again with `calibctl rig export RIG --format kalibr-imu`"
    findings = []
    for key in sorted(KALIBR_IMU_FIELDS):
        v = data[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v) or v <= 0:
            findings.append(_error("kalibr", f"{key} = {v!r} is not a positive number", fix))
    model = data.get("model", "calibrated")
    if model not in ("calibrated", "scale-misalignment"):
        findings.append(_error("kalibr", f"model {model!r} is not one calibctl writes", fix))
    elif model == "scale-misalignment":  # Kalibr's own result fields for the model: 3x3, finite
        gyro, accel = data.get("gyroscopes") or {}, data.get("accelerometers") or {}
        for what, value in (
            ("gyroscopes.M", gyro.get("M")),
            ("gyroscopes.A", gyro.get("A")),
            ("accelerometers.M", accel.get("M")),
        ):
            findings += _finite_matrix(value, (3, 3), what)[1]
        C, bad = _finite_matrix(gyro.get("C_gyro_i"), (3, 3), "gyroscopes.C_gyro_i")
        findings += bad + ([] if C is None else _rotation(C, "gyroscopes.C_gyro_i"))
    return findings


def _kalibr_target(data: dict[str, Any]) -> list[Finding]:
    """Kalibr's target.yaml as its ConfigReader ``getTargetParams`` checks it: an aprilgrid's tagCols and
    tagRows ints of 3 or more, tagSize and tagSpacing positive floats; a checkerboard's targetCols and
    targetRows likewise, rowSpacingMeters and colSpacingMeters positive floats (Kalibr refuses an int)."""
    fix = "export it again with `calibctl rig export RIG --format kalibr-target`"
    kind = data.get("target_type")
    fields = _KALIBR_TARGETS.get(kind) if isinstance(kind, str) else None
    if fields is None:
        return [_error("kalibr", f"target_type {kind!r} is not aprilgrid or checkerboard", fix)]
    findings = []
    for key, want in fields.items():
        v = data.get(key)
        whole = type(v) is int and v >= 3  # bool is no int here: type(True) is bool
        ok = whole if want is int else type(v) is float and bool(np.isfinite(v)) and v > 0
        if not ok:
            what = "an int of 3 or more" if want is int else "a positive float"
            findings.append(_error("kalibr", f"{key} = {v!r} is not {what} (Kalibr refuses it)", fix))
    return findings


def _opencv_stereo(text: str, source: str, limits: LintThresholds, trace: Trace) -> list[Finding]:
    data = formats.opencv_data(text, source)
    findings: list[Finding] = []
    R, bad = _finite_matrix(data.get("R"), (3, 3), "R")
    findings += bad + ([] if R is None else _rotation(R, "R (T_right_left)"))
    _, bad = _finite_matrix(data.get("T"), (3, 1), "T")
    findings += bad
    size = [data.get("image_width"), data.get("image_height")]
    for cam in ("1", "2"):
        K, bad = _finite_matrix(data.get(f"K{cam}"), (3, 3), f"K{cam}")
        findings += bad
        if K is not None:
            dist = list(np.ravel(data.get(f"D{cam}") or []))
            facts = _camera_facts(
                f"{source}:K{cam}", K, dist, size, data.get("distortion_model") == "equidistant"
            )
            findings += [
                f.model_copy(update={"message": f"camera {cam}: {f.message}"})
                for f in trace.lint(facts, limits)
            ]
    return findings


def _mrcal(model: dict[str, Any], source: str, limits: LintThresholds, trace: Trace) -> list[Finding]:
    lens, intr = str(model.get("lensmodel")), model.get("intrinsics")
    fix = "export it again with `calibctl rig export RIG --format bundle`"
    n = {
        "LENSMODEL_OPENCV4": 4,
        "LENSMODEL_OPENCV5": 5,
        "LENSMODEL_OPENCV8": 8,
        "LENSMODEL_OPENCV12": 12,
    }.get(lens)
    if n is None:
        return [
            _error(
                "mrcal",
                f"lensmodel {lens} is not one calibctl writes (LENSMODEL_OPENCV4/5/8/12)",
                fix,
                "warning",
            )
        ]
    values, bad = _finite_matrix(intr, (1, 4 + n), "intrinsics")
    _, bad_ext = _finite_matrix(model.get("extrinsics"), (1, 6), "extrinsics")
    if values is None:
        return bad + bad_ext
    fx, fy, cx, cy = values[0, :4]
    facts = _camera_facts(
        source,
        np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]]),
        list(values[0, 4:]),
        model.get("imagersize"),
        False,
    )
    return bad_ext + trace.lint(facts, limits)


def _imu_edge(data: dict[str, Any], source: str) -> list[Finding]:
    """One camera-IMU edge as ``rig export --edge IMU:CAM --format json`` writes it: its schema, and a
    warning that it carries no seal of its own (its rig version's content hash and signature cover it)."""
    from calibctl.artifacts.imu import ImuEdgeResult

    try:
        ImuEdgeResult.model_validate(data)
    except ValidationError as exc:
        return [_error("schema", validation_message(exc, source), "re-export it from the store")]
    return [
        _error(
            "traceability",
            f"{source} is one edge of a rig version: it carries no content hash of its own, so an edited "
            "number cannot be found here",
            "lint the rig version it came from: `calibctl rig export RIG --format json` (sealed, signed)",
            "warning",
        )
    ]


def _document(
    data: dict[str, Any], source: str, model: type[RigCalibration] | type[HandEyeResult]
) -> list[Finding]:
    try:
        doc = model.model_validate(data)
    except ValidationError as exc:
        return [
            _error(
                "schema",
                validation_message(exc, source),
                "re-export it from the store; never edit one by hand",
            )
        ]
    if doc.computed_sha256() != doc.content_sha256:
        return [
            _error(
                "content-hash",
                f"content sha256 is {doc.computed_sha256()[:12]} but the file records "
                f"{doc.content_sha256[:12]}: it was changed after it was written",
                "re-export it from the store",
            )
        ]
    from calibctl.artifacts.rig import RigCalibration
    from calibctl.workflows.lint import evidence  # numpy, boards: only for a rig document

    problems = evidence.rig_evidence_problems(doc, {}) if isinstance(doc, RigCalibration) else []
    if problems:  # a number moved and the hash recomputed: the version contradicts itself
        return [
            _error(
                "evidence",
                f"{source} does not reproduce its own evidence: {'; '.join(problems)}",
                "re-export it from the store; never edit one by hand, re-hashed or not",
            )
        ]
    return (
        []
        if doc.status == "accepted"
        else [_error("status", f"{source} is a {doc.status} version", "export an accepted version")]
    )


SIGNATURE_FIX = (
    "load only what a signing store exported: `calibctl keys init` on the store that solves the rig, "
    "then trust its public key (--trusted-keys DIR)"
)


def _seal(
    what: str, seal: RecordSignature | None, content_sha256: str, trusted: TrustedKeys
) -> list[Finding]:
    problem = keys.seal_problem(seal, content_sha256, trusted)
    return [] if problem is None else [_error("signature", f"{what} {problem}", SIGNATURE_FIX)]


def _seal_of(value: Any) -> RecordSignature | None:
    try:
        return None if value is None else RecordSignature.model_validate(value)
    except ValidationError:
        return None


def _manifest_seal(data: dict[str, Any], trusted: TrustedKeys) -> list[Finding]:
    """The manifest's own signature (by the exporting store's key): the export's choices (frame names,
    roles, the pair, each file's sha256) that no rig signature covers."""
    seal = data.get(bundle.MANIFEST_SIGNATURE)
    if not isinstance(seal, dict):
        return [
            _error(
                "signature",
                "the manifest is not signed: its frame names and file roles are the exporter's choice, "
                "which only the manifest's own signature covers",
                "export the bundle again from a store with a key (`calibctl rig export RIG --format bundle`)",
            )
        ]
    problem = trusted.check(
        seal.get("key_id"), seal.get("value"), bundle.manifest_message(data), seal.get("public_key")
    )
    problem = f"{problem}: {EDITED}" if is_mismatch(problem) else problem
    return [] if problem is None else [_error("signature", f"the manifest {problem}", SIGNATURE_FIX)]


def _bundle_signatures(data: dict[str, Any], trusted: TrustedKeys) -> list[Finding]:
    """The manifest's own signature, its rig signature and each member's (a robot loads the members'
    numbers too)."""
    findings = _manifest_seal(data, trusted) + _seal(
        f"rig {data.get('rig')}@{data.get('version')}",
        _seal_of(data.get("signature")),
        str(data.get("content_sha256")),
        trusted,
    )
    for m in data.get("members") or []:
        if isinstance(m, dict):
            findings += _seal(
                f"member {m.get('serial')}@{m.get('version')}",
                _seal_of(m.get("signature")),
                str(m.get("content_sha256")),
                trusted,
            )
    return findings


def _camera_signature(header: trace_header.TraceHeader, trusted: TrustedKeys) -> list[Finding]:
    """A camera export's ``calibctl signature`` header line, over the artifact's content hash it names."""
    if header.signature is None:
        return [
            _error(
                "signature",
                f"{header.ref}: this file carries no signature line (exported before calibctl wrote one, or "
                "from a store without a key)",
                f"export it again: `calibctl export {header.ref} --format ...` from the store that holds it "
                "writes the artifact's signature; a store without a key signs nothing (`calibctl keys init` "
                "there, then solve or import the calibration again)",
            )
        ]
    return _seal(header.ref, header.signature, header.artifact_sha256, trusted)


def _file_signature(
    header: trace_header.RigTraceHeader | trace_header.TraceHeader, trusted: TrustedKeys, in_bundle: bool
) -> list[Finding]:
    """The exporting store's signature of the file itself (``trace_header.sign_file``): the header's record
    signature covers the version it names, not the numbers in the file. Not asked of a file a bundle's
    signed manifest lists (the manifest signs its sha256); one it carries is still checked."""
    seal = header.file_signature
    if seal is None:
        if in_bundle:
            return []
        return [
            _error(
                "signature",
                "the file itself is not signed: the header's signature covers the version it names, not the "
                "numbers below it (anyone can edit one and recompute the file-sha256 line)",
                "export it again from a store with its signing key configured (`calibctl keys init` there): "
                "the export then carries a `calibctl file-signature` line",
            )
        ]
    problem = trusted.check(seal.key_id, seal.value, seal.message, seal.public_key)
    return [] if problem is None else [_error("signature", f"the file {problem}", SIGNATURE_FIX)]


def _header_signature(
    header: trace_header.RigTraceHeader | None,
    trusted: TrustedKeys,
    camera: trace_header.TraceHeader | None = None,
    in_bundle: bool = False,
) -> list[Finding]:
    """A rig export's header signature, over the rig version's content hash the header names; a camera
    export's (``camera``, no rig header) over the artifact's; then the file's own (``_file_signature``)."""
    found = _record_signature(header, trusted, camera)
    signed = header if header is not None else camera
    return found if signed is None else found + _file_signature(signed, trusted, in_bundle)


def _record_signature(
    header: trace_header.RigTraceHeader | None,
    trusted: TrustedKeys,
    camera: trace_header.TraceHeader | None = None,
) -> list[Finding]:
    if header is None and camera is not None:
        return _camera_signature(camera, trusted)
    if header is None:
        return [_error("signature", "no calibctl rig header: nothing vouches for this file", SIGNATURE_FIX)]
    if header.ref == trace_header.NOT_STORED:
        return [
            _error(
                "signature",
                "written by `rig solve-folders` from no stored rig version: nothing signs it",
                "store the rig (`calibctl rig solve`) and export it from a signing store",
            )
        ]
    return _seal(f"rig {header.ref}", header.signature, header.rig_sha256, trusted)


def _derived(manifest_path: Path, data: dict[str, Any]) -> list[Finding]:
    """The bundle against what its rig.json derives (``rig_bundle.check_derived``); a rig.json missing or
    edited leaves nothing to check the files against: an error."""
    from calibctl.artifacts.rig import RigCalibration
    from calibctl.workflows.exports import rig_bundle  # OpenCV: only for a bundle

    path = manifest_path.parent / rig_bundle.RIG_JSON
    fix = "export the bundle again (`calibctl rig export RIG@N --format bundle -o DIR --force`)"
    if not path.is_file():
        return [_error("bundle", f"{path} is missing: nothing vouches for the bundle's files", fix)]
    try:
        cal = RigCalibration.model_validate(bounded.parse_json(bounded.read_text(path), str(path)))
    except (ValidationError, InputError) as exc:
        return [_error("bundle", f"{path} is not a readable rig version ({exc})", fix)]
    if cal.computed_sha256() != cal.content_sha256:
        return [
            _error("bundle", f"{path} was edited (its content hash does not match): no file is checked", fix)
        ]
    return rig_bundle.check_derived(manifest_path, data, cal)


def _role(header: trace_header.RigTraceHeader | None, data: Any) -> list[Finding]:
    """A rig camera_info whose header names one camera (``member SERIAL@V ... frame F``) and whose
    ``camera_name`` is another's: the numbers of one camera under another's name."""
    if header is None or len(header.members) != 1 or not isinstance(data, dict):
        return []
    ref, _, frame = header.members[0]
    name = data.get("camera_name")
    if frame is None or not isinstance(name, str):
        return []
    if name == FrameNames({ref: frame}).camera_name(ref):
        return []
    return [
        _error(
            "frames",
            f"its header names {ref} (frame {frame}) but its camera_name is {name}: one camera's file under "
            "another's name",
            "export it again (`calibctl rig export RIG --format ros -o DIR`); never edit one by hand",
        )
    ]


def lint_camera_file(
    path: Path,
    limits: LintThresholds,
    trusted: TrustedKeys | None = None,
    store: Settings | None = None,
    in_bundle: bool = False,
) -> LintResult:
    """A camera export, ROS or OpenCV file (a rig's camera_info too); with ``trusted`` its signature: the
    artifact's, or the rig version's in a rig export's header; with ``store`` (--db) its numbers against
    the version its header names (``store_match``)."""
    loaded = formats.load_calibration(path)
    result = lint_file(loaded, limits)
    if store is not None and (facts := file_facts(loaded)) is not None:
        result.findings.extend(store_match.store_findings(store, loaded, facts))
    result.findings.extend(_role(loaded.rig_header, loaded.data))
    if trusted is not None and (loaded.rig_header is not None or loaded.kind != "calibctl" and loaded.header):
        result.findings.extend(_header_signature(loaded.rig_header, trusted, loaded.header, in_bundle))
    elif trusted is not None:
        signature_rule(result, loaded.data if loaded.kind == "calibctl" else {}, trusted)
    return result


def lint_rig_file(
    path: Path, limits: LintThresholds, trusted: TrustedKeys | None = None, in_bundle: bool = False
) -> list[LintResult] | None:
    """The lint of a rig export file (a bundle: its manifest's result, then one per listed file), or None
    when ``path`` is not one. ``trusted`` (``--require-signature``): the rig version's signature must be a
    trusted key's (a bundle's members' too)."""
    text, source = bounded.read_text(path), str(path)
    data = _parse(text, source)
    kind = rig_file_kind(text, data)
    if kind is None:
        return None
    if kind == "bundle":
        signed = [] if trusted is None else _bundle_signatures(data, trusted)
        results = [LintResult(source, kind, bundle.check_bundle(path, data) + _derived(path, data) + signed)]
        for entry in data.get("files") or []:
            listed = path.parent / str(entry.get("path", "")) if isinstance(entry, dict) else None
            if listed is not None and listed.is_file() and listed.resolve().parent == path.parent.resolve():
                results += lint_rig_file(listed, limits, trusted, in_bundle=True) or [
                    lint_camera_file(listed, limits, trusted, in_bundle=True)
                ]
        return results
    if kind in ("rig-json", "handeye-json"):
        from calibctl.artifacts.handeye import HandEyeResult
        from calibctl.artifacts.rig import RigCalibration

        model = RigCalibration if kind == "rig-json" else HandEyeResult
        findings = _document(data, source, model)
        if trusted is not None and kind == "rig-json":
            findings += _seal(
                f"rig {data.get('rig')}@{data.get('version')}",
                _seal_of(data.get("signature")),
                str(data.get("content_sha256")),
                trusted,
            )
        elif trusted is not None:
            findings.append(
                _error(
                    "signature",
                    "a hand-eye result is signed as part of its rig version, not alone",
                    "lint the rig version it belongs to: `calibctl rig export RIG --format json`",
                )
            )
        return [LintResult(source, kind, findings)]
    if kind == "imu-edge-json":
        return [LintResult(source, kind, _imu_edge(data, source))]
    if kind in (sealed_result.LIDAR_RESULT, sealed_result.IMU_RESULT):
        return [LintResult(source, kind, _sealed_result(data, source, trusted or TrustedKeys(), kind))]
    camera, rig = trace_header.read(text), trace_header.read_rig(text)
    findings, evidence = trace_rules(camera, rig)
    if trusted is not None:
        findings += _header_signature(rig, trusted, camera, in_bundle)
    if camera is None and rig is None:
        findings = [
            _error(
                "traceability",
                "no calibctl header: this file cannot be traced to a stored version; "
                "linted on its numbers and frames only",
                "export it with `calibctl rig export RIG --format ...` or `calibctl export SERIAL`",
                "warning",
            )
        ]
    trace = Trace(trace_of(evidence, camera, rig), evidence)
    if kind == "tf":
        findings += _tf(data)
    elif kind == "urdf":
        findings += _urdf(data)
    elif kind == "mrcal":
        findings += _mrcal(data["mrcal"], source, limits, trace)
    elif kind == "kalibr":
        findings += _kalibr(data, source, limits, trace)
    elif kind == "kalibr-imu":
        findings += _kalibr_imu(data)
    elif kind == "kalibr-target":
        findings += _kalibr_target(data)
    else:
        findings += _opencv_stereo(text, source, limits, trace)
    return [LintResult(source, kind, findings)]
