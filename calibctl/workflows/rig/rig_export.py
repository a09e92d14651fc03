"""``calibctl rig export``: one stored rig version as the files a robot loads (workflows.exports.rig_exports),
named by the robot's frames (workflows.exports.frame_names), each stamped with the rig's trace header.

- single-file formats (json, opencv, tf, urdf, urdf-joints, kalibr, kalibr-imu) -> ``export`` returns the
  text (kalibr-imu: Kalibr's imu.yaml of the version's camera-IMU edge);
- ``ros`` -> ``export_files``: one camera_info file per camera (ROS reads only the first YAML document of
  a file, so two cameras in one file made a stereo driver run the left calibration on the right camera);
- ``bundle`` -> ``export_files``: every format at once plus manifest.json (workflows.exports.bundle);
- ``lut`` -> ``export_files``: each stereo pair's rectification maps for both cameras (workflows.exports.lut).
A rejected version, or one that ``rig lint`` fails now (a stale member, a failed gate), is refused unless
allowed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibctl import __version__
from calibctl.artifacts.imu import ImuEdgeResult
from calibctl.artifacts.lint import Finding
from calibctl.artifacts.rig import RigCalibration
from calibctl.config import Settings
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics
from calibctl.core.extrinsics.rig_tree import RigTree
from calibctl.errors import NotFoundError, UsageError, VerdictFailed
from calibctl.files import file_errors, write_atomic
from calibctl.workflows.edges.export import edge_export
from calibctl.workflows.edges.kinds import STALE_RULES, evidence_of
from calibctl.workflows.edges.versions import cal_versions, edge_findings
from calibctl.workflows.exports import bundle, lut, mrcal_model, rig_exports, trace_header
from calibctl.workflows.exports.frame_names import FrameNames, parse_frame_map
from calibctl.workflows.rig.rig_lint import parse_rig_ref, rig_findings
from calibctl.workflows.store_admin.records import open_store

EXPORT_FORMATS = (
    "json",
    "opencv",
    "ros",
    "tf",
    "urdf",
    "urdf-joints",
    "kalibr",
    "kalibr-imu",
    "bundle",
    "lut",
)
FILE_FORMATS = ("ros", "bundle", "lut")  # written as several files: export_files
ROS_ONE_FILE_FIX = (
    "ROS reads only the first YAML document of a file (a stereo driver would load the left "
    "calibration for the right camera): pass -o DIR (one CAMERA.yaml per camera) or "
    "-o 'DIR/{camera}.yaml'"
)


@dataclass(frozen=True)
class RigExport:
    """A stored rig version ready to export: its geometry by serial and the robot's frame names."""

    cal: RigCalibration
    members: list[MemberIntrinsics]
    cameras: RigTree  # the rig-solve edges only, serials
    full_tree: RigTree  # hand-eye and LiDAR edges included, serials and declared frames
    names: FrameNames
    left: str
    right: str
    member_docs: dict[str, dict[str, Any]]  # serial -> its manifest entry (signature from the store)

    @property
    def ref(self) -> str:
        return f"{self.cal.rig}@{self.cal.version}"

    def T_right_left(self) -> np.ndarray:
        return self.cameras.T(self.right, self.left)

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


def _refuse_unloadable(
    cal: RigCalibration, findings: list[Finding], allow_rejected: bool, allow_stale: bool
) -> None:
    """A rejected version is exit 2; one `rig lint` fails now for a stale member (or the camera of an
    evidence edge) exit 1."""
    ref = f"rig {cal.rig}@{cal.version}"
    if cal.status != "accepted" and not allow_rejected:
        raise UsageError(
            f"{ref} is {cal.status}: a robot must not load it",
            hint="export the active version, or pass --allow-rejected to inspect it",
        )
    stale = [f for f in findings if f.severity == "error" and f.rule in STALE_RULES]
    if stale and not (allow_stale or allow_rejected):
        raise VerdictFailed(
            f"{ref} fails `calibctl rig lint` now: {stale[0].message}",
            f"{stale[0].fix}; or pass --allow-stale to export it anyway (a robot must not load it)",
        )


def _prepare(
    settings: Settings, ref: str, pair: str | None, frames: list[str], allow_rejected: bool, allow_stale: bool
) -> RigExport:
    name, version = parse_rig_ref(ref)
    with open_store(settings) as store:
        rig = store.get_rig(name)
        cal = store.get_rig_calibration(name, version)
        stored: dict[str, Any] = {}
        active: dict[str, Any] = {}
        for m in cal.members:
            try:
                stored[m.serial] = store.get_artifact(m.serial, m.version)
            except NotFoundError:
                stored[m.serial] = None
            try:
                active[m.serial] = store.get_artifact(m.serial, None)
            except NotFoundError:
                active[m.serial] = None
        findings = rig_findings(cal, rig, active, settings.lint)
        findings += edge_findings(evidence_of(cal), cal_versions(store, cal))
    _refuse_unloadable(cal, findings, allow_rejected, allow_stale)
    members, cameras, full_tree = rig_exports.stored_geometry(cal)
    serials = [m.serial for m in cal.members]
    others = [f for f in full_tree.frames if f not in serials]
    names = FrameNames.of(serials, others, parse_frame_map(frames, [*serials, *others]))
    right = pair or next(s for s in serials if s != cal.root)
    if right not in serials or right == cal.root:
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
            "signature": (
                stored[m.serial].signature.model_dump(mode="json")
                if stored[m.serial] is not None and stored[m.serial].signature
                else None
            ),
        }
        for m in cal.members
    }
    return RigExport(cal, members, cameras, full_tree, names, cal.root, right, member_docs)


def _text(x: RigExport, fmt: str) -> str:
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
        return x.stamp(rig_exports.kalibr_imu(ev.noise, f"/{frame}"))
    # opencv
    return x.stamp(
        rig_exports.opencv_stereo(by_name[x.left], by_name[x.right], x.T_right_left()), (x.left, x.right)
    )


def export(
    settings: Settings,
    ref: str,
    fmt: str,
    out: Path | None,
    *,
    force: bool,
    pair: str | None = None,
    allow_rejected: bool = False,
    allow_stale: bool = False,
    edge: str | None = None,
    frames: list[str] | None = None,
) -> str:
    """A stored rig calibration as one file of ``fmt``: the text, also written to ``out`` when given.
    ``edge`` FROM:TO exports one hand-eye edge (json or tf)."""
    if fmt not in EXPORT_FORMATS:
        raise UsageError(f"unknown rig export format '{fmt}'", f"choose one of {', '.join(EXPORT_FORMATS)}")
    if fmt in FILE_FORMATS:
        raise UsageError(
            f"--format {fmt} writes one file per camera, not one text",
            ROS_ONE_FILE_FIX if fmt == "ros" else "pass -o DIR",
        )
    x = _prepare(settings, ref, pair, frames or [], allow_rejected, allow_stale)
    if edge is None:
        text = _text(x, fmt)
    else:  # one evidence edge: its tf carries the rig header (and signature) like every rig export
        text = edge_export(x.cal, edge, fmt, x.names.frames)
        text = x.stamp(text) if fmt == "tf" else text
    if out is not None:
        write_atomic(out, text, force=force)
    return text


def _ros_paths(out: Path, x: RigExport) -> dict[str, Path]:
    """serial -> its camera_info path under ``-o DIR`` or ``-o 'DIR/{camera}.yaml'``."""
    if "{camera}" in str(out):
        paths = {m.name: Path(str(out).replace("{camera}", x.names.camera_name(m.name))) for m in x.members}
    elif out.suffix.lower() in (".yaml", ".yml") and not out.is_dir():
        raise UsageError(f"-o {out}: a stereo rig is not one camera_info file", ROS_ONE_FILE_FIX)
    else:
        with file_errors("create the export folder", out):
            out.mkdir(parents=True, exist_ok=True)
        paths = {m.name: out / f"{x.names.camera_name(m.name)}.yaml" for m in x.members}
    return paths


def _camera_infos(x: RigExport, *, mono_if_vertical: bool) -> tuple[dict[str, str], bool]:
    """serial -> stamped camera_info, and whether the pair got its rectified R/P (False: a vertical pair)."""
    infos, rectified = rig_exports.ros_camera_infos(
        x.members, x.left, x.right, x.T_right_left(), x.names, mono_if_vertical=mono_if_vertical
    )
    return {s: x.stamp(text, (s,)) for s, text in infos.items()}, rectified


def _bundle_files(x: RigExport) -> tuple[dict[str, str], dict[str, Any]]:
    """Every file of the bundle (name -> text) and what the manifest says about them."""
    infos, rectified = _camera_infos(x, mono_if_vertical=True)
    files = {f"{x.names.camera_name(s)}.yaml": text for s, text in infos.items()}
    by_name = {m.name: m for m in x.members}
    pairs = []
    for e in x.cameras.edges:
        name = f"stereo_{x.names.camera_name(e.parent)}_{x.names.camera_name(e.child)}.yaml"
        files[name] = x.stamp(
            rig_exports.opencv_stereo(by_name[e.parent], by_name[e.child], x.cameras.T(e.child, e.parent)),
            (e.parent, e.child),
        )
        pairs.append({"left": e.parent, "right": e.child, "opencv": name})
    files["tf_static.yaml"] = _text(x, "tf")
    files["rig.urdf"] = _text(x, "urdf")
    files["camchain.yaml"] = _text(x, "kalibr")
    if x.imu_edge() is not None:
        files["imu.yaml"] = _text(x, "kalibr-imu")
    files["rig.json"] = _text(x, "json")
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
        "stereo": {"left": x.left, "right": x.right, "rectified_camera_info": rectified},
        "stereo_pairs": pairs,
    }
    return files, manifest


def _lut_files(x: RigExport) -> tuple[dict[str, bytes], str]:
    """Per camera edge (the bundle's stereo pairs): both cameras' rectification maps and the stamped lut.yaml
    with the rig version's JSON beside it (lint checks the header's numbers against it)."""
    cameras = lut.rig_cameras(
        x.cal,
        x.members,
        x.cameras,
        lambda left, right, serial: (
            f"stereo_{x.names.camera_name(left)}_{x.names.camera_name(right)}.{x.names.camera_name(serial)}"
        ),
        x.names.frame,
    )
    payloads, entries = lut.build(cameras)
    payloads[lut.RIG_DOCUMENT] = _text(x, "json").encode("utf-8")
    source = lut.source_of("rig", x.ref, x.cal.status, x.cal.content_sha256, payloads[lut.RIG_DOCUMENT])
    serials = tuple(dict.fromkeys(c.serial for c in cameras))
    return payloads, x.stamp(lut.header_body(source, entries), serials)


def export_files(
    settings: Settings,
    ref: str,
    fmt: str,
    out: Path | None,
    *,
    force: bool,
    pair: str | None = None,
    allow_rejected: bool = False,
    allow_stale: bool = False,
    frames: list[str] | None = None,
) -> list[Path]:
    """``ros`` (one camera_info per camera), ``bundle`` (every file + manifest.json) or ``lut`` (each stereo
    pair's rectification maps + lut.yaml) into ``out``."""
    if out is None:
        raise UsageError(
            f"--format {fmt} writes several files", ROS_ONE_FILE_FIX if fmt == "ros" else "pass -o DIR"
        )
    x = _prepare(settings, ref, pair, frames or [], allow_rejected, allow_stale)
    if fmt == "lut":
        payloads, header = _lut_files(x)
        return lut.write_lut(out, payloads, header, force=force)
    if fmt == "bundle":
        files, manifest = _bundle_files(x)
        return bundle.write_bundle(out, files, manifest, force=force)
    texts, _ = _camera_infos(
        x, mono_if_vertical=False
    )  # a vertical pair is refused before any folder is made
    paths = _ros_paths(out, x)
    for serial, path in paths.items():
        if path.exists() and not force:  # check every target before writing any: nothing half-written
            write_atomic(path, texts[serial], force=False)
    return [write_atomic(path, texts[serial], force=force) for serial, path in paths.items()]
