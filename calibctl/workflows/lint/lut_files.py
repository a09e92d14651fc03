"""Lint of an undistortion LUT (``calibctl export --format lut`` / ``rig export --format lut``): the folder or
its lut.yaml (workflows.exports.lut).

- the header's trace lines: an edited lut.yaml is ``content-hash``, a rejected source ``status``;
- each map (rule ``lut``): named inside the folder, present, not truncated, a .npy of the header's type and of
  the header's image size, its sha256 the header's;
- the maps derived again by OpenCV from the header's numbers (K, distortion, R, P, image size) must be the
  files' (``lut``): float maps within 1e-3 px, the fixed-point pair within its 1/32 px cell;
- ``--require-signature``: the source's store signature (a camera's ``signature`` line, a rig's
  ``rig-signature``) by a trusted key, over the content hash the header names;
- ``--db``: the source must be the active version in that store (``lut-stale``), with the same content hash.
"""

from __future__ import annotations

import hashlib
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from calibctl import bounded
from calibctl.artifacts.common import validation_message
from calibctl.artifacts.lint import Finding
from calibctl.config import Settings
from calibctl.errors import InputError, NotFoundError
from calibctl.signing import TrustedKeys
from calibctl.workflows.exports import lut, trace_header
from calibctl.workflows.lint.lint import LintResult, trace_rules
from calibctl.workflows.store_admin import keys

FLOAT_TOLERANCE_PX = 1e-3
_SIGNATURE_FIX = (
    "export the LUT from a signing store (`calibctl keys init` there), and trust its public key "
    "(--trusted-keys DIR)"
)


def _error(message: str, fix: str, rule: str = "lut") -> Finding:
    return Finding(rule=rule, severity="error", message=message, fix=fix)


def header_path(path: Path) -> Path | None:
    """lut.yaml of a LUT folder, or ``path`` itself when it is a LUT header; None for anything else."""
    if path.is_dir():
        return path / lut.HEADER if (path / lut.HEADER).is_file() else None
    if not path.is_file():  # a FIFO is never opened here (bounded.read_text refuses it, naming it)
        return None
    try:
        with path.open("rb") as handle:
            head = handle.read(4096).decode("utf-8", errors="replace")
    except OSError:
        return None
    return path if lut.looks_like_lut(head) else None


def _source_ref(camera: trace_header.TraceHeader | None, rig: trace_header.RigTraceHeader | None) -> str:
    return camera.ref if camera else rig.ref if rig else "?"


def _reexport(
    camera: trace_header.TraceHeader | None, rig: trace_header.RigTraceHeader | None, folder: Path
) -> str:
    if rig is not None:
        return (
            f"export it again: `calibctl rig export {rig.ref.split('@')[0]} --format lut -o {folder} --force`"
        )
    serial = camera.ref.split("@")[0] if camera else "SERIAL"
    return f"export it again: `calibctl export {serial} --format lut -o {folder} --force`"


def _load_map(
    path: Path, entry: dict[str, Any], size: tuple[int, int], fix: str
) -> tuple[Any, list[Finding]]:
    """The map at ``path`` when it is the file the header lists, else the finding naming what is wrong."""
    from calibctl.core.intrinsics import undistort_maps

    name = str(entry.get("map"))
    if name not in undistort_maps.MAP_TYPES:
        return None, [_error(f"{path}: '{name}' is not a map calibctl writes", fix)]
    expected_bytes = entry.get("bytes")
    actual_bytes = path.stat().st_size
    if isinstance(expected_bytes, int) and actual_bytes < expected_bytes:
        return None, [_error(f"{path} is truncated ({actual_bytes} of {expected_bytes} bytes)", fix)]
    try:
        array = np.load(path, mmap_mode="r", allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        return None, [_error(f"{path} is not a readable .npy map ({exc})", fix)]
    shape, want = tuple(array.shape), undistort_maps.expected_shape(name, size)
    if shape[:2] != want[:2]:
        return None, [
            _error(
                f"{path} is a map for {shape[1] if len(shape) > 1 else '?'}x{shape[0]} images; this LUT is "
                f"for {size[0]}x{size[1]}",
                fix,
            )
        ]
    if shape != want or str(array.dtype) != undistort_maps.MAP_TYPES[name][1]:
        return None, [
            _error(
                f"{path} holds {array.dtype} {shape}, not the {undistort_maps.MAP_TYPES[name][0]} map", fix
            )
        ]
    with path.open("rb") as handle:
        actual = hashlib.sha256(handle.read()).hexdigest()
    if actual != entry.get("sha256"):
        return None, [
            _error(
                f"{path} was changed after calibctl wrote it (sha256 {actual[:12]}, lut.yaml records "
                f"{str(entry.get('sha256'))[:12]})",
                fix,
            )
        ]
    return np.asarray(array), []


def _derived(camera: dict[str, Any], loaded: dict[str, np.ndarray], source: str, fix: str) -> list[Finding]:
    """The maps OpenCV derives from the header's numbers against the files (once every file checked out)."""
    from calibctl.core.intrinsics import undistort_maps

    try:
        size = (int(camera["image_size"][0]), int(camera["image_size"][1]))
        lens: undistort_maps.Lens = "fisheye" if camera.get("lens") == "fisheye" else "pinhole"
        K, D = np.asarray(camera["camera_matrix"], float), np.asarray(camera["dist_coeffs"], float)
        R, P = np.asarray(camera["R"], float), np.asarray(camera["P"], float)
        again = undistort_maps.maps(K.reshape(3, 3), D, size, lens, R.reshape(3, 3), P)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        return [
            _error(f"{source}: the numbers of camera {camera.get('name')} cannot build a map ({exc})", fix)
        ]
    findings = []
    for axis in ("x", "y"):
        name = f"map_{axis}_32f"
        if name in loaded:
            gap = float(np.nanmax(np.abs(loaded[name].astype(np.float64) - again[name])))
            if not gap <= FLOAT_TOLERANCE_PX:
                findings.append(
                    _error(
                        f"{source}: {camera.get('name')}.{name} is not the map its numbers give (off by up "
                        f"to {gap:.3g} px)",
                        fix,
                    )
                )
    if "map1_16sc2" in loaded and "map2_16uc1" in loaded:
        x, y = undistort_maps.decode_fixed(loaded["map1_16sc2"], loaded["map2_16uc1"])
        inside = (np.abs(again["map_x_32f"]) < 3e4) & (np.abs(again["map_y_32f"]) < 3e4)
        cell = 1.0 / undistort_maps.FIXED_POINT_CELLS + FLOAT_TOLERANCE_PX
        gap = max(
            float(np.max(np.abs(x - again["map_x_32f"])[inside], initial=0.0)),
            float(np.max(np.abs(y - again["map_y_32f"])[inside], initial=0.0)),
        )
        if gap > cell:
            findings.append(
                _error(
                    f"{source}: {camera.get('name')}'s fixed-point maps are not the map its numbers give "
                    f"(off by up to {gap:.3g} px)",
                    fix,
                )
            )
    return findings


def _plain_name(name: str) -> bool:
    """A file right in the LUT's folder: no folder part, absolute path or '..'."""
    rel = PurePosixPath(name)
    return "\\" not in name and not rel.is_absolute() and len(rel.parts) == 1 and name not in (".", "..")


def _maps(folder: Path, data: dict[str, Any], source: str, fix: str) -> list[Finding]:
    findings: list[Finding] = []
    for camera in data["cameras"]:
        if not isinstance(camera, dict) or not isinstance(camera.get("maps"), list):
            findings.append(_error(f"{source}: a camera entry has no maps", fix))
            continue
        size_value = camera.get("image_size")
        if not (
            isinstance(size_value, list)
            and len(size_value) == 2
            and all(isinstance(v, int) for v in size_value)
        ):
            findings.append(_error(f"{source}: camera {camera.get('name')} has no image_size [w, h]", fix))
            continue
        size = (size_value[0], size_value[1])
        loaded: dict[str, np.ndarray] = {}
        problems: list[Finding] = []
        for entry in camera["maps"]:
            name = entry.get("path") if isinstance(entry, dict) else None
            if not isinstance(name, str):
                problems.append(_error(f"{source}: a map of camera {camera.get('name')} has no path", fix))
                continue
            if not _plain_name(name):
                problems.append(_error(f"{source} names a map outside its folder: {name!r}", fix))
                continue
            path = folder / name
            if path.is_symlink() or not path.is_file():
                problems.append(_error(f"{path} is listed in {lut.HEADER} but missing", fix))
                continue
            array, bad = _load_map(path, entry, size, fix)
            problems += bad
            if array is not None:
                loaded[str(entry["map"])] = array
        findings += problems or _derived(camera, loaded, source, fix)
    return findings


_NUMBER_TOLERANCE = {"camera_matrix": 1e-9, "dist_coeffs": 1e-12, "R": 1e-9, "P": 1e-6, "T_right_left": 1e-12}


def _expected_cameras(doc: Any, data: dict[str, Any], rig: bool) -> dict[tuple[Any, ...], Any]:
    """(serial, pair) -> the LutCamera the source document gives (a camera: at the header's alpha/balance)."""
    from calibctl.workflows.exports import rig_exports

    if rig:
        members, cameras, _ = rig_exports.stored_geometry(doc)
        built = lut.rig_cameras(doc, members, cameras, lambda *_: "", lambda _: None)
        return {(c.serial, c.pair): c for c in built}
    entry = data["cameras"][0]
    lens: Any = "fisheye" if doc.model.name == "fisheye" else "pinhole"
    given = entry.get("balance" if lens == "fisheye" else "alpha")
    number = isinstance(given, int | float) and not isinstance(given, bool)
    free = float(given) if number else 0.0  # a value that is no number is flagged by _against_source
    camera = lut.single_camera(
        doc.serial,
        doc.version,
        doc.content_sha256,
        "",
        lens,
        doc.camera_matrix,
        doc.dist_coeffs,
        doc.image_size,
        free,
    )
    return {(camera.serial, None): camera}


def _same(value: Any, expected: np.ndarray, tolerance: float) -> bool:
    try:
        got = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return got.shape == expected.shape and bool(np.all(np.abs(got - expected) <= tolerance))


def _against_source(
    folder: Path,
    data: dict[str, Any],
    camera: trace_header.TraceHeader | None,
    rig: trace_header.RigTraceHeader | None,
    source: str,
    fix: str,
) -> list[Finding]:
    """The header's numbers against the source document in the folder, whose content hash is the one the
    header (and its signature) names: an edited K with maps built from it is refused here."""
    from pydantic import ValidationError

    from calibctl.artifacts.calibration import CalibrationArtifact
    from calibctl.artifacts.rig import RigCalibration

    if camera is None and rig is None:
        return []
    name = (data.get("source") or {}).get("document") if isinstance(data.get("source"), dict) else None
    if not isinstance(name, str) or not _plain_name(name):
        return [_error(f"{source} names no source document in its folder ({name!r})", fix)]
    path = folder / name
    if path.is_symlink() or not path.is_file():
        return [_error(f"{path} is missing: nothing ties the maps' numbers to the calibration", fix)]
    text = bounded.read_text(path)
    if hashlib.sha256(text.encode("utf-8")).hexdigest() != data["source"].get("document_sha256"):
        return [_error(f"{path} was changed after calibctl wrote it (its sha256 is not lut.yaml's)", fix)]
    model: Any = RigCalibration if rig is not None else CalibrationArtifact
    named = rig.rig_sha256 if rig is not None else camera.artifact_sha256 if camera else ""
    try:
        doc = model.model_validate(bounded.parse_json(text, str(path)))
    except ValidationError as exc:
        return [_error(validation_message(exc, str(path)), fix)]
    if doc.computed_sha256() != doc.content_sha256 or doc.content_sha256 != named:
        return [
            _error(
                f"{path} is not the calibration lut.yaml names (content sha256 {doc.computed_sha256()[:12]}, "
                f"the header names {named[:12]})",
                fix,
            )
        ]
    expected = _expected_cameras(doc, data, rig is not None)
    entries = data["cameras"]
    keys_seen = [
        (c.get("serial"), tuple(c["rectified_pair"]) if isinstance(c.get("rectified_pair"), list) else None)
        for c in entries
    ]
    if sorted(map(str, keys_seen)) != sorted(map(str, expected)):
        return [_error(f"{source} lists other cameras than {path.name} gives", fix)]
    findings = []
    for entry, key in zip(entries, keys_seen, strict=True):
        want = expected[key]
        numbers = {
            "camera_matrix": want.camera_matrix,
            "dist_coeffs": np.ravel(want.dist_coeffs),
            "R": want.R,
            "P": want.P,
            **({"T_right_left": want.T_right_left} if want.T_right_left is not None else {}),
        }
        wrong = [
            k
            for k, v in numbers.items()
            if not _same(entry.get(k), np.asarray(v, float), _NUMBER_TOLERANCE[k])
        ]
        if entry.get("image_size") != list(want.image_size) or entry.get("lens") != want.lens:
            wrong.insert(0, "image_size / lens")
        # alpha / balance: a pair's is stereoRectify's -1, a camera's the number its P came from
        free_key = "balance" if want.lens == "fisheye" else "alpha"
        if entry.get(free_key) != (-1.0 if want.free is None else want.free):
            wrong.append(free_key)
        if wrong:
            findings.append(
                _error(
                    f"{source}: {entry.get('serial')}'s {', '.join(wrong)} are not what {path.name} (the "
                    "calibration the header names) gives",
                    fix,
                )
            )
    return findings


def _signature(
    camera: trace_header.TraceHeader | None, rig: trace_header.RigTraceHeader | None, trusted: TrustedKeys
) -> list[Finding]:
    if camera is not None:
        seal, subject, what = camera.signature, camera.artifact_sha256, camera.ref
    elif rig is not None:
        seal, subject, what = rig.signature, rig.rig_sha256, f"rig {rig.ref}"
    else:
        return [_error("no calibctl header: nothing vouches for this LUT", _SIGNATURE_FIX, "signature")]
    problem = keys.seal_problem(seal, subject, trusted)
    return [] if problem is None else [_error(f"{what} {problem}", _SIGNATURE_FIX, "signature")]


def _stale(
    settings: Settings,
    camera: trace_header.TraceHeader | None,
    rig: trace_header.RigTraceHeader | None,
    fix: str,
) -> list[Finding]:
    """``lut-stale`` unless the source is the active version (same content hash) in the store."""
    from calibctl.workflows.store_admin.records import open_store

    if camera is None and rig is None:
        return []
    ref = _source_ref(camera, rig)
    name, _, version = ref.partition("@")
    with open_store(settings) as store:
        try:
            if rig is not None:
                active = store.get_rig_calibration(name, None)
                current, sha, built_sha = active.version, active.content_sha256, rig.rig_sha256
            else:
                found = store.get_artifact(name, None)
                current, sha = found.version, found.content_sha256
                built_sha = camera.artifact_sha256 if camera else ""
        except NotFoundError:
            return [_error(f"{ref}: the store {store.url} has no active version of {name}", fix, "lut-stale")]
    what = f"rig {name}" if rig is not None else name
    if str(current) != version:
        return [
            _error(
                f"this LUT was built from {ref}, but the active version of {what} is {current}: a robot "
                "would undistort with a calibration that was replaced",
                fix,
                "lut-stale",
            )
        ]
    if sha != built_sha:
        return [
            _error(
                f"this LUT was built from {ref} sha256 {built_sha[:12]}, but this store's {ref} is "
                f"{sha[:12]}: another store's calibration",
                fix,
                "lut-stale",
            )
        ]
    return []


def lint_lut(path: Path, trusted: TrustedKeys | None, store: Settings | None) -> list[LintResult] | None:
    """The lint of a LUT folder or header, or None when ``path`` is neither. ``store``: refuse a stale LUT."""
    header = header_path(path)
    if header is None:
        return None
    text, source = bounded.read_text(header), str(header)
    data = bounded.parse_yaml(text, source)
    if not isinstance(data, dict) or data.get("format") != lut.LUT_FORMAT:
        raise InputError(f"{source} is not a calibctl LUT header", "export it with --format lut")
    camera, rig = trace_header.read(text), trace_header.read_rig(text)
    fix = _reexport(camera, rig, header.parent)
    findings, _ = trace_rules(camera, rig)
    if camera is None and rig is None:
        findings = [_error(f"{source}: no calibctl header: this LUT cannot be traced to a calibration", fix)]
    cameras = data.get("cameras")
    if not isinstance(cameras, list) or not cameras or not all(isinstance(c, dict) for c in cameras):
        findings.append(_error(f"{source} lists no cameras (a list of camera entries)", fix))
    else:
        findings += _against_source(header.parent, data, camera, rig, source, fix)
        findings += _maps(header.parent, data, source, fix)
    if trusted is not None:
        findings += _signature(camera, rig, trusted)
    if store is not None:
        findings += _stale(store, camera, rig, fix)
    return [LintResult(source, "lut", findings)]
