"""``calibctl rig export``: one stored rig version as the files a robot loads (workflows.exports.rig_exports),
named by the robot's frames (workflows.exports.frame_names), each stamped with the rig's trace header.

- single-file formats (json, opencv, tf, urdf, urdf-joints, kalibr, kalibr-imu, kalibr-target) -> ``export``
  returns the text (kalibr-imu: Kalibr's imu.yaml of the version's camera-IMU edge; kalibr-target: Kalibr's
  target.yaml of the registered board that edge was solved with, read from the store);
- ``ros`` -> ``export_files``: one camera_info file per camera (ROS reads only the first YAML document of
  a file, so two cameras in one file made a stereo driver run the left calibration on the right camera);
- ``bundle`` -> ``export_files``: every format at once plus manifest.json (workflows.exports.bundle);
- ``lut`` -> ``export_files``: each stereo pair's rectification maps for both cameras (workflows.exports.lut).
A rejected version, or one that ``rig lint`` fails now (a stale member, a failed gate), is refused unless
allowed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from calibctl.artifacts.lint import Finding
from calibctl.artifacts.rig import RigCalibration
from calibctl.config import Settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.errors import NotFoundError, UsageError, VerdictFailed
from calibctl.files import file_errors, write_atomic
from calibctl.workflows.edges.export import edge_export
from calibctl.workflows.edges.kinds import STALE_RULES, evidence_of
from calibctl.workflows.edges.versions import cal_versions, edge_findings
from calibctl.workflows.exports import bundle, lut, rig_bundle, rig_exports
from calibctl.workflows.exports.frame_names import parse_frame_map
from calibctl.workflows.exports.rig_bundle import RigExport
from calibctl.workflows.exports.rig_bundle import bundle_files as _bundle_files
from calibctl.workflows.exports.rig_bundle import camera_infos as _camera_infos
from calibctl.workflows.exports.rig_bundle import text as _text
from calibctl.workflows.rig.rig_lint import parse_rig_ref, rig_findings
from calibctl.workflows.store_admin import keys
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
    "kalibr-target",
    "bundle",
    "lut",
)
FILE_FORMATS = ("ros", "bundle", "lut")  # written as several files: export_files
ROS_ONE_FILE_FIX = (
    "ROS reads only the first YAML document of a file (a stereo driver would load the left "
    "calibration for the right camera): pass -o DIR (one CAMERA.yaml per camera) or "
    "-o 'DIR/{camera}.yaml'"
)


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
        cal = keys.with_public_key(store.get_rig_calibration(name, version), store.trusted)
        stored: dict[str, Any] = {}
        active: dict[str, Any] = {}
        for m in cal.members:
            try:
                stored[m.serial] = keys.with_public_key(
                    store.get_artifact(m.serial, m.version), store.trusted
                )
            except NotFoundError:
                stored[m.serial] = None
            try:
                active[m.serial] = store.get_artifact(m.serial, None)
            except NotFoundError:
                active[m.serial] = None
        findings = rig_findings(cal, rig, active, settings.lint)
        findings += edge_findings(evidence_of(cal), cal_versions(store, cal))
    _refuse_unloadable(cal, findings, allow_rejected, allow_stale)
    _, _, full_tree = rig_exports.stored_geometry(cal)
    serials = [m.serial for m in cal.members]
    others = [f for f in full_tree.frames if f not in serials]
    signatures = {
        s: a.signature.model_dump(mode="json") if a is not None and a.signature else None
        for s, a in stored.items()
    }
    return rig_bundle.derive(cal, parse_frame_map(frames, [*serials, *others]), pair, signatures)


def _imu_board(settings: Settings, x: RigExport) -> tuple[BoardSpec, str]:
    """The registered board the version's camera-IMU edge was solved with (``imu solve --board``)."""
    from calibctl.workflows.board.boards import board_ref, board_spec

    ev = x.imu_edge()
    rerun = f"calibctl imu solve RECORDING --serial CAM --board BOARD --rig {x.cal.rig}"
    if ev is None:
        raise NotFoundError(
            f"rig {x.ref} has no accepted camera-IMU edge: no target.yaml to export",
            f"solve one with `{rerun}`",
        )
    if ev.board is None:
        raise NotFoundError(
            f"the camera-IMU edge of rig {x.ref} was solved from corner files without --board: "
            "no registered board to write as target.yaml",
            f"register the board (`calibctl board add`) and solve again with it: `{rerun}`",
        )
    with open_store(settings) as store:
        board = store.get_board(*board_ref(ev.board))
    return board_spec(board), board.ref


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
    if edge is None and fmt == "kalibr-target":
        text = x.stamp(rig_exports.kalibr_target(*_imu_board(settings, x)))
    elif edge is None:
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
        return bundle.write_bundle(out, files, manifest, force=force, signer=keys.signer_of(settings))
    texts, _ = _camera_infos(
        x, mono_if_vertical=False
    )  # a vertical pair is refused before any folder is made
    paths = _ros_paths(out, x)
    for serial, path in paths.items():
        if path.exists() and not force:  # check every target before writing any: nothing half-written
            write_atomic(path, texts[serial], force=False)
    return [write_atomic(path, texts[serial], force=force) for serial, path in paths.items()]
