"""Every file of a rig version's robot bundle, derived from the version alone, and the check that a bundle on
disk is exactly that: the seal of what a robot loads.

A bundle's files are a pure function of its ``rig.json`` (the rig version, content hash re-derived, its
signature verifiable) and the manifest's choices (the frame names, the stereo pair, the members'
signatures). ``derive`` builds the export from those, ``bundle_files`` writes every file's text;
``rig export --format bundle`` and ``calibctl lint`` / ``rig import`` of a bundle run the same code. So a
file whose numbers were edited (its ``file-sha256`` line and the manifest entry recomputed: checksums
anyone can forge) or two camera files swapped (each header naming another camera than its role) differ
from what ``rig.json`` derives, and are refused: the signature on ``rig.json`` covers every file.

Floats are compared to 1e-9 (relative, or absolute near zero: a file written by the same calibctl is
byte-identical; the margin is for another platform's last bits, far below a pixel or a micrometre), every
other token (integers, names, hashes) exactly.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibctl import __version__, bounded
from calibctl.artifacts.imu import ImuEdgeResult
from calibctl.artifacts.lint import Finding
from calibctl.artifacts.rig import RigCalibration
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics
from calibctl.core.extrinsics.rig_tree import RigTree
from calibctl.errors import NotFoundError, UsageError
from calibctl.files import file_errors
from calibctl.workflows.exports import mrcal_model, rig_exports, trace_header
from calibctl.workflows.exports.frame_names import FrameNames

RIG_JSON = "rig.json"
# a float standing alone; integers and the digits of a name, a hash or a version are words, compared exactly
_NUMBER = re.compile(r"(?<![\w.+-])[-+]?(?:(?:\d+\.\d*|\.\d+)(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+)(?![\w.])")
_HASH_LINE = re.compile(r"^(?:# |<!-- )calibctl file-sha256 ", re.M)
REL_TOL = 1e-9


@dataclass(frozen=True)
class RigExport:
    """A stored rig version ready to export: its geometry by serial and the robot's frame names."""

    cal: RigCalibration
    members: list[MemberIntrinsics]
    cameras: RigTree  # the rig-solve edges only, serials
    full_tree: RigTree  # hand-eye and LiDAR edges included, serials and declared frames
    names: FrameNames
    left: str
    right: str | None  # None: a one-camera rig, no stereo pair
    member_docs: dict[str, dict[str, Any]]  # serial -> its manifest entry (signature from the store)

    @property
    def ref(self) -> str:
        return f"{self.cal.rig}@{self.cal.version}"

    def stereo_pair(self) -> tuple[str, str, np.ndarray] | None:
        """(left, right, T_right_left) of the stereo pair; None for a one-camera rig."""
        return None if self.right is None else (self.left, self.right, self.cameras.T(self.right, self.left))

    def stamp(self, body: str, serials: tuple[str, ...] = ()) -> str:
        by = {m.serial: m for m in self.cal.members}
        members = tuple((f"{s}@{by[s].version}", by[s].content_sha256, self.names.frame(s)) for s in serials)
        return trace_header.stamp_rig(
            self.ref, self.cal.status, self.cal.content_sha256, body, members, self.cal.signature
        )

    def imu_edge(self) -> ImuEdgeResult | None:
        """The accepted camera-IMU evidence of this version (its edge is in the tree), if any."""
        return next((ev for ev in self.cal.imu if ev.status == "accepted" and ev.estimate is not None), None)

    def imu_timeshift_s(self) -> float:
        """Kalibr's timeshift_cam_imu: the camera-IMU edge's td_s (the rig's cameras share one clock), or
        0.0 for an IMU joined by hand-eye."""
        ev = self.imu_edge()
        return 0.0 if ev is None or ev.estimate is None else ev.estimate.td_s

    def imu_transforms(self) -> dict[str, np.ndarray] | None:
        """serial -> T_cam_imu when the tree has one IMU frame (a camera-IMU edge's, or a declared frame
        named ``*imu*``)."""
        ev = self.imu_edge()
        named = [f for f in self.full_tree.frames if f not in self.cameras.frames and "imu" in f.lower()]
        imus = list(dict.fromkeys(([ev.parent_frame] if ev is not None else []) + named))
        if len(imus) > 1:
            raise UsageError(
                f"rig {self.ref} has several IMU frames ({', '.join(imus)}); Kalibr's camchain takes one"
            )
        return {c: self.full_tree.T(c, imus[0]) for c in self.cameras.frames} if imus else None

    def overlaps(self) -> dict[str, set[str]]:
        """Cameras that saw the board together (the pairs' shared views), Kalibr's cam_overlaps."""
        out: dict[str, set[str]] = {c: set() for c in self.cameras.frames}
        for p in self.cal.pairs:
            if p.shared_views > 0:
                out[p.a].add(p.b)
                out[p.b].add(p.a)
        return out


def derive(
    cal: RigCalibration,
    mapped: Mapping[str, str],
    pair: str | None,
    member_signatures: Mapping[str, dict[str, Any] | None],
) -> RigExport:
    """The export of ``cal`` with the frames ``mapped`` (serial or frame -> ROS frame; the rest default), the
    stereo pair's right camera ``pair`` (None: the second member) and each member's signature document."""
    members, cameras, full_tree = rig_exports.stored_geometry(cal)
    serials = [m.serial for m in cal.members]
    others = [f for f in full_tree.frames if f not in serials]
    names = FrameNames.of(serials, others, mapped)
    if len(serials) == 1 and pair is not None:
        raise UsageError(
            f"--pair {pair}: rig {cal.rig} has one camera, no stereo pair",
            hint="leave --pair out: its exports describe the one camera and its sensor edges",
        )
    right = pair or next((s for s in serials if s != cal.root), None)
    if right is not None and (right not in serials or right == cal.root):
        raise UsageError(f"--pair {right} is not a non-root member of rig {cal.rig}")
    member_docs = {
        m.serial: {
            "serial": m.serial,
            "version": m.version,
            "content_sha256": m.content_sha256,
            "frame_id": names.frame(m.serial),
            "camera_name": names.camera_name(m.serial),
            "rostopic": names.topic(m.serial),
            "lens": m.lens,
            "signature": member_signatures.get(m.serial),
        }
        for m in cal.members
    }
    return RigExport(cal, members, cameras, full_tree, names, cal.root, right, member_docs)


def text(x: RigExport, fmt: str) -> str:
    """One single-file format (json, tf, urdf, urdf-joints, kalibr, kalibr-imu, opencv) of the export,
    stamped."""
    by_name = {m.name: m for m in x.members}
    if fmt == "json":
        return x.cal.model_dump_json(indent=2) + "\n"
    if fmt == "tf":
        return x.stamp(rig_exports.tf_static(x.names.tree(x.full_tree)))
    if fmt == "urdf":
        return x.stamp(rig_exports.urdf_robot(x.names.tree(x.full_tree), x.cal.rig))
    if fmt == "urdf-joints":
        return x.stamp(rig_exports.urdf_joints(x.names.tree(x.full_tree)))
    if fmt == "kalibr":
        return x.stamp(
            rig_exports.kalibr_camchain(
                x.members, x.cameras, x.names, x.overlaps(), x.imu_transforms(), x.imu_timeshift_s()
            )
        )
    if fmt == "kalibr-imu":
        ev = x.imu_edge()
        if ev is None:
            raise NotFoundError(
                f"rig {x.ref} has no accepted camera-IMU edge: no imu.yaml to export",
                f"solve one with `calibctl imu solve RECORDING --serial CAM --rig {x.cal.rig}`",
            )
        frame = x.names.frames.get(ev.parent_frame, ev.parent_frame)
        model = None if ev.estimate is None else ev.estimate.imu_model
        return x.stamp(rig_exports.kalibr_imu(ev.noise, f"/{frame}", model))
    # opencv
    stereo = x.stereo_pair()
    if stereo is None:
        raise UsageError(
            f"rig {x.ref} has one camera: the OpenCV stereo file needs two",
            hint="export its camera with `calibctl export SERIAL --format opencv`, or the rig as ros, tf, "
            "urdf, kalibr or bundle",
        )
    left, right, T_right_left = stereo
    return x.stamp(rig_exports.opencv_stereo(by_name[left], by_name[right], T_right_left), (left, right))


def camera_infos(x: RigExport, *, mono_if_vertical: bool) -> tuple[dict[str, str], bool]:
    """serial -> stamped camera_info, and whether the pair got its rectified R/P (False: a vertical pair)."""
    infos, rectified = rig_exports.ros_camera_infos(
        x.members, x.stereo_pair(), x.names, mono_if_vertical=mono_if_vertical
    )
    return {s: x.stamp(body, (s,)) for s, body in infos.items()}, rectified


def bundle_files(x: RigExport) -> tuple[dict[str, str], dict[str, Any]]:
    """Every file of the bundle (name -> text) and what the manifest says about them."""
    infos, rectified = camera_infos(x, mono_if_vertical=True)
    files = {f"{x.names.camera_name(s)}.yaml": body for s, body in infos.items()}
    by_name = {m.name: m for m in x.members}
    pairs = []
    for e in x.cameras.edges:
        name = f"stereo_{x.names.camera_name(e.parent)}_{x.names.camera_name(e.child)}.yaml"
        files[name] = x.stamp(
            rig_exports.opencv_stereo(by_name[e.parent], by_name[e.child], x.cameras.T(e.child, e.parent)),
            (e.parent, e.child),
        )
        pairs.append({"left": e.parent, "right": e.child, "opencv": name})
    files["tf_static.yaml"] = text(x, "tf")
    files["rig.urdf"] = text(x, "urdf")
    files["camchain.yaml"] = text(x, "kalibr")
    if x.imu_edge() is not None:
        files["imu.yaml"] = text(x, "kalibr-imu")
    files[RIG_JSON] = text(x, "json")
    members = []
    for m in x.members:
        doc = dict(x.member_docs[m.name], camera_info=f"{x.names.camera_name(m.name)}.yaml")
        model = mrcal_model.cameramodel(
            m, x.full_tree.T(m.name, x.cal.root), f"calibctl rig {x.ref} member {m.name}@{doc['version']}"
        )
        if model is None:
            doc["mrcal"] = None
            doc["mrcal_missing"] = mrcal_model.missing_reason(m)
        else:
            doc["mrcal"] = f"{x.names.camera_name(m.name)}.cameramodel"
            files[doc["mrcal"]] = x.stamp(model, (m.name,))
        members.append(doc)
    manifest = {
        "rig": x.cal.rig,
        "version": x.cal.version,
        "status": x.cal.status,
        "content_sha256": x.cal.content_sha256,
        "signature": x.cal.signature.model_dump(mode="json") if x.cal.signature else None,
        "calibctl_version": __version__,
        "root_frame": x.names.frame(x.full_tree.root),
        "frames": dict(x.names.frames),
        "members": members,
        "stereo": (
            None
            if x.right is None
            else {"left": x.left, "right": x.right, "rectified_camera_info": rectified}
        ),
        "stereo_pairs": pairs,
    }
    return files, manifest


def _tokens(body: str) -> tuple[list[str], list[float]]:
    """The words of ``body`` (numbers replaced by one marker) and its numbers; the file-hash line dropped."""
    kept = "".join(line for line in body.splitlines(keepends=True) if not _HASH_LINE.match(line))
    numbers = [float(n) for n in _NUMBER.findall(kept)]
    return _NUMBER.sub("#", kept).split(), numbers


def same_content(a: str, b: str) -> bool:
    """Equal text, or the same words and the same numbers to ``REL_TOL`` (another platform's last bits)."""
    if a == b:
        return True
    (wa, na), (wb, nb) = _tokens(a), _tokens(b)
    return (
        wa == wb
        and len(na) == len(nb)
        and bool(np.allclose(na, nb, rtol=REL_TOL, atol=REL_TOL, equal_nan=False))
    )


def _finding(message: str, fix: str) -> Finding:
    return Finding(rule="bundle", severity="error", message=message, fix=fix)


_CHOSEN = ("calibctl_version",)  # the manifest says which calibctl wrote it: no seal needed


def derive_from_manifest(cal: RigCalibration, manifest: Mapping[str, Any]) -> RigExport:
    """The export ``rig export --format bundle`` made of ``cal`` with the manifest's choices."""
    frames, stereo = manifest.get("frames"), manifest.get("stereo")
    frames, stereo = (
        (frames if isinstance(frames, dict) else {}),
        (stereo if isinstance(stereo, dict) else {}),
    )
    signatures = {
        str(m.get("serial")): m.get("signature")
        for m in manifest.get("members") or []
        if isinstance(m, dict) and isinstance(m.get("signature"), dict)
    }
    known = {m.serial for m in cal.members} | {f for e in cal.edges for f in (e.parent, e.child)}
    mapped = {str(k): str(v) for k, v in frames.items() if k in known}
    return derive(
        cal, mapped, stereo.get("right") if isinstance(stereo.get("right"), str) else None, signatures
    )


def check_derived(manifest_path: Path, manifest: Mapping[str, Any], cal: RigCalibration) -> list[Finding]:
    """Every way the bundle beside ``manifest_path`` differs from what ``cal`` (its verified rig.json)
    derives: a file missing, extra or not listed, a file whose numbers, frames or camera differ, the
    manifest's own claims (members, frames, pairs, roles). Empty: the bundle is exactly rig.json's."""
    folder = manifest_path.parent
    fix = (
        f"export the bundle again from the store that holds it (`calibctl rig export {cal.ref} --format "
        "bundle -o DIR --force`); never edit one by hand: every file is derived from rig.json and checked "
        "against it"
    )
    try:
        x = derive_from_manifest(cal, manifest)
        files, derived = bundle_files(x)
    except (UsageError, ValueError, KeyError) as exc:
        return [_finding(f"{manifest_path}: its frames or stereo pair do not fit {cal.ref} ({exc})", fix)]
    findings = [
        _finding(
            f"{manifest_path}: '{key}' is {manifest.get(key)!r}, but {RIG_JSON} ({cal.ref}) derives "
            f"{derived[key]!r}",
            fix,
        )
        for key in derived
        if key not in _CHOSEN and manifest.get(key) != derived[key]
    ]
    listed = [e.get("path") for e in manifest.get("files") or [] if isinstance(e, dict)]
    findings += [
        _finding(f"{manifest_path}: lists {name}, which {RIG_JSON} ({cal.ref}) derives no file for", fix)
        for name in listed
        if name not in files
    ]
    findings += [
        _finding(f"{manifest_path}: does not list {name}, which {RIG_JSON} ({cal.ref}) derives", fix)
        for name in files
        if name not in listed
    ]
    for name in (n for n in files if n in listed):
        path = folder / name
        if not path.is_file() or path.is_symlink():
            continue  # check_bundle names a missing file
        bounded.check_size(path)
        with file_errors("read", path):
            on_disk = path.read_text(encoding="utf-8", errors="replace")
        if same_content(on_disk, files[name]):
            continue
        other = next((n for n, body in files.items() if n != name and same_content(on_disk, body)), None)
        what = (
            f"holds what {RIG_JSON} derives for {other}: another camera or role than its name"
            if other is not None
            else f"differs from what {RIG_JSON} ({cal.ref}) derives for it (its numbers, frames or header)"
        )
        findings.append(_finding(f"{path} {what}", fix))
    return findings
