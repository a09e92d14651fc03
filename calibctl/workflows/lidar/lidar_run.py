"""``calibctl lidar solve`` as one workflow call: the rig target checked, the solve, the rig's next version
(``--rig``) and the files (``-o``, ``--tf-static``); the CLI parses, calls ``run_lidar`` and renders.

Order (docs/lidar.md): with ``--rig`` the target is refused before any scan is read (exit 2, nothing stored:
rig_lidar module docstring); then the solve (lidar_solve), its evidence stored as the rig's next version,
then the files. ``-o`` holds ``lidar_solve.result_json`` (the rounded shape ``--json`` prints, without the
``stored`` block) sealed (``exports.sealed_result``: its kind, content hash and, with a configured key, its
signature); ``--tf-static`` is written for an accepted result only.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from calibctl.config import Settings
from calibctl.errors import AlreadyExistsError, UsageError
from calibctl.files import existing_target, write_atomic
from calibctl.workflows.exports import sealed_result
from calibctl.workflows.lidar import rig_lidar
from calibctl.workflows.lidar.lidar_solve import (
    LidarOutcome,
    LidarRequest,
    result_json,
    run_lidar_solve,
    tf_static_yaml,
)
from calibctl.workflows.store_admin import keys


@dataclass(frozen=True)
class RigTarget:
    """``--rig RIG``: the edge ``lidar_frame -> --serial`` of that rig; ``board`` as the evidence names it."""

    rig: str
    lidar_frame: str
    board: str


@dataclass(frozen=True)
class LidarFiles:
    """``-o`` (the result JSON), ``--tf-static`` (accepted only, frames as named), ``--force``."""

    out: Path | None = None
    tf_static: Path | None = None
    lidar_frame: str = "lidar"
    camera_frame: str = "camera"
    force: bool = False


def run_lidar(
    settings: Settings, req: LidarRequest, files: LidarFiles, target: RigTarget | None = None
) -> LidarOutcome:
    """The whole command (module docstring); ``outcome.written`` lists the files, ``outcome.stored`` the
    rig version written."""
    if files.tf_static is not None:
        check_tf_frames(files.lidar_frame, files.camera_frame)
    check_targets_free(files)
    if target is not None:
        if req.camera_info is not None:
            raise UsageError(
                "--rig takes the camera as --serial (its active calibration), not --camera-info",
                "the rig edge pins the calibration it was solved with",
            )
        rig_lidar.check_target(settings, target.rig, target.lidar_frame, req.serial)
    outcome = run_lidar_solve(settings, req)
    if target is not None:
        ev = rig_lidar.evidence(outcome, req, target.lidar_frame, req.serial or "", target.board)
        outcome.stored = rig_lidar.store_lidar(settings, target.rig, ev).calibration
    outcome.written = [f"wrote {path}" for path in outcome.overlays or []]
    doc = result_json(outcome)
    if files.out is not None:  # hashed, and signed with a configured key: `lint FILE` checks both
        sealed = sealed_result.seal(doc, sealed_result.LIDAR_RESULT, keys.signer_of(settings))
        text = json.dumps(sealed, indent=2, allow_nan=False) + "\n"
        write_atomic(files.out, text, force=files.force)
        outcome.written.append(f"wrote {files.out}")
    if files.tf_static is not None:
        if outcome.accepted:
            yaml = tf_static_yaml(doc, files.lidar_frame, files.camera_frame)
            write_atomic(files.tf_static, yaml, force=files.force)
            outcome.written.append(f"wrote {files.tf_static}")
        else:
            outcome.written.append(f"not written: {files.tf_static} (rejected: no transform is published)")
    return outcome


def check_targets_free(files: LidarFiles) -> None:
    """``-o`` and ``--tf-static`` refused before the solve when they exist without ``--force``
    (AlreadyExistsError, exit 2): checked after the solve, a rig version would be stored and its files
    not written."""
    if files.force:
        return
    for path in (files.out, files.tf_static):
        if path is not None and existing_target(path) is not None:
            raise AlreadyExistsError(
                f"{path} already exists; nothing was solved or stored", "pass --force to overwrite it"
            )


def check_tf_frames(lidar_frame: str, camera_frame: str) -> None:
    """The frames ``--tf-static`` would write: each a legal ROS frame name (UsageError, exit 2, before the
    solve), as a rig export's are; tf2 rejects a transform between frames such as ``bad name!``."""
    from calibctl.workflows.exports.frame_names import NAME_RULE, is_ros_name

    for option, name, example in (
        ("--lidar-frame", lidar_frame, "velodyne"),
        ("--camera-frame", camera_frame, "camera_optical_frame"),
    ):
        if not is_ros_name(name):
            raise UsageError(
                f"{option} {name!r} is not a legal ROS frame name, so --tf-static cannot carry it",
                f"{NAME_RULE}; e.g. {option} {example}",
            )
