"""Robot-arm hand-eye: base->gripper poses from the robot, board->camera poses from the camera's images.

The CSV has one row per arm pose: ``image`` (file name inside --images) and the gripper pose
``T_base_gripper`` as ``gripper_q*``/``gripper_r*_rad``/``gripper_r11..r33`` + ``gripper_t*_m`` (metres;
see handeye_io). A file without a header, 16 numbers per line (a row-major 4x4, metres, as RWHE-Calib's
RobotPosesVec.txt), is read too: its i-th line is the i-th image of --images in file-name order. Each image is
detected and its board pose fitted on the camera's *active* calibration from the store, through that
calibration's lens model (solvePnP for pinhole models, the fisheye projection for ``--model fisheye``). Then,
with the board frame as b's world:

- eye-in-hand (camera on the gripper): a = gripper in the base frame, X = T_gripper_camera;
- eye-to-hand (camera fixed, board on the gripper): a = base seen from the gripper (inverse robot
  pose), X = T_base_camera.

Images where the board is not found are skipped with the reason; a missing or unreadable image, an
image of another size than the calibration, or a camera with no active calibration is exit 2.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.config import Settings
from calibctl.core.capture.detect import detect_board
from calibctl.core.capture.image_outcomes import list_images
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.board_pose import estimate_board_pose
from calibctl.core.extrinsics.handeye import Motions
from calibctl.core.gate import GateResult
from calibctl.errors import InputError, UsageError, named_list
from calibctl.workflows.board.boards import board_ref, board_spec
from calibctl.workflows.board.gauge_failures import failure_fix, failure_text
from calibctl.workflows.diagnostics import diagnostics_io as dio
from calibctl.workflows.handeye import handeye_io
from calibctl.workflows.handeye.handeye import (
    HandEyeOutcome,
    Outputs,
    Source,
    check_frames,
    solve_result,
    thresholds,
)
from calibctl.workflows.handeye.handeye import write_outputs as _write_outputs
from calibctl.workflows.store_admin.records import open_store

if TYPE_CHECKING:
    from calibctl.store.gauge_failures import GaugeFailure

PREFIX = "gripper"
MIN_POSES = 3


def _read_matrix_rows(path: Path, images: Path) -> tuple[dio.Table, np.ndarray] | None:
    """A pose file without a header (handeye_io.read_matrix_rows): line i is the i-th image in name order."""
    read = handeye_io.read_matrix_rows(path)
    if read is None:
        return None
    T_base_gripper, lines = read
    names = [p.name for p in list_images(images)]
    if len(names) != len(lines):
        raise InputError(
            f"{path.name} has {len(lines)} poses but {images} has {len(names)} images; a pose file "
            "without image names pairs its i-th pose with the i-th image in file-name order",
            hint="keep exactly the images the poses were recorded for in --images, or write the CSV "
            "with an image column",
        )
    return dio.Table(path, {}, {"image": np.array(names)}, lines), T_base_gripper


def _read_robot_csv(path: Path, images: Path) -> tuple[dio.Table, np.ndarray]:
    matrix_rows = _read_matrix_rows(path, images)
    if matrix_rows is not None:
        table, T_base_gripper = matrix_rows
    else:
        table = dio.read_table(
            path,
            handeye_io.translation_columns(PREFIX),
            optional_numeric=handeye_io.all_pose_columns(PREFIX),
            optional_text=("image",),
            what="robot poses CSV",
        )
        if "image" not in table.text:
            raise InputError(
                f"{path.name} has no image column", hint="one row per arm pose: image, gripper pose columns"
            )
        T_base_gripper = handeye_io.read_transforms(table, PREFIX)
    reach = np.linalg.norm(T_base_gripper[:, :3, 3], axis=1)
    far = reach > handeye_io.ROBOT_REACH_MAX_M
    if far.any():
        raise InputError(
            f"{path.name}: gripper translation {reach.max():.4g} at {dio.lines_text(table.lines[far])} is "
            f"beyond any arm's reach in metres: millimetres?",
            hint="robot controllers often report mm; divide the gripper_t*_m columns by 1000",
        )
    return table, T_base_gripper


def _board_poses(
    table: dio.Table, images: Path, art: CalibrationArtifact, spec
) -> tuple[list, list[str], list[str]]:
    """Per row: T_cam_board or None; the skipped rows with reasons; sha256 of every image read."""
    K, dist = np.array(art.camera_matrix, np.float64), np.array(art.dist_coeffs, np.float64)
    model = spec.object_points()
    poses: list[np.ndarray | None] = []
    skipped, hashes = [], []
    for name, line in zip(table.text["image"], table.lines, strict=True):
        path = images / str(name)
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise InputError(
                f"{table.path.name} line {int(line)}: cannot read image {path}: {exc.strerror or exc}",
                hint="the image column names files inside --images",
            ) from None
        gray = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE) if data else None
        if gray is None:
            raise InputError(f"{table.path.name} line {int(line)}: {path} is not a readable image")
        if (gray.shape[1], gray.shape[0]) != tuple(art.image_size):
            raise InputError(
                f"{path.name} is {gray.shape[1]}x{gray.shape[0]} but {art.ref} was fitted at "
                f"{art.image_size[0]}x{art.image_size[1]}",
                hint="use images at the calibration's resolution (K scales with the read-out)",
            )
        hashes.append(hashlib.sha256(data).hexdigest())
        detection, reason = detect_board(gray, spec)
        T_cam_board, rms = (
            (None, float("inf"))
            if detection is None
            else estimate_board_pose(
                model[detection.corner_ids], detection.corners_px, K, dist, art.model.name
            )
        )
        if T_cam_board is None:
            skipped.append(f"{path.name} (line {int(line)}): {reason or 'no board pose'}")
        poses.append(T_cam_board)
    return poses, skipped, hashes


def _load_camera(settings: Settings, serial: str, board: str | None):
    """The camera's active calibration, the board revision, and their failed metric gauges by revision."""
    with open_store(settings) as store:
        art = store.get_artifact(serial)  # NotFoundError (exit 2) without an active calibration
        revision = art.board if board is None else store.get_board(*board_ref(board))
        return art, revision, store.failed_gauges({art.board.ref, revision.ref})


def gauge_gate(art: CalibrationArtifact, failures: Mapping[str, Sequence[GaugeFailure]]) -> GateResult | None:
    """``metric-gauge``: the board revision of the photos or of the camera's calibration has a failed gauge
    (seed chapter 0: every translation is scaled by it). Passed when the calibration overrode it with a
    recorded reason; None when there is nothing to judge."""
    if not failures:
        return None
    ref, found = sorted(failures.items())[0]
    message = failure_text(ref, found)
    override = art.provenance.gauge_override
    if override:
        return GateResult(
            "metric-gauge",
            True,
            abs(found[0].ratio - 1),
            0.01,
            f"{message}; overridden in {art.ref}: {override}",
        )
    return GateResult(
        "metric-gauge",
        False,
        abs(found[0].ratio - 1),
        0.01,
        message,
        reason="metric_gauge.board_failed",
        hint=failure_fix(ref, f"calibrate {art.serial} with --override-gauge REASON"),
    )


def run_robot_handeye(
    settings: Settings,
    path: Path,
    images: Path | None,
    serial: str | None,
    parent_frame: str,
    child_frame: str,
    *,
    board_ref: str | None = None,
    eye_to_hand: bool = False,
    method: str = "park",
    lever_arm_sigma_min: float | None = None,
    outputs: Outputs | None = None,
) -> HandEyeOutcome:
    check_frames(parent_frame, child_frame)
    if images is None or serial is None:
        raise UsageError("the robot-arm case needs both --images DIR and --serial SERIAL")
    if not images.is_dir():
        raise InputError(f"--images {images} is not a folder")
    table, T_base_gripper = _read_robot_csv(path, images)
    art, board, failures = _load_camera(settings, serial, board_ref)
    poses, skipped, hashes = _board_poses(table, images, art, board_spec(board))
    keep = [i for i, T in enumerate(poses) if T is not None]
    if len(keep) < MIN_POSES:
        raise InputError(
            f"{path.name}: the board was found in {len(keep)} of {len(poses)} images; hand-eye needs "
            f"at least {MIN_POSES} poses",
            hint=named_list(skipped, 3, sep="; ") or None,
        )
    T_wa_a = (
        T_base_gripper[keep] if not eye_to_hand else np.array([se3.invert(T) for T in T_base_gripper[keep]])
    )
    T_board_cam = np.array([se3.invert(poses[i]) for i in keep])
    labels = tuple(str(table.text["image"][i]) for i in keep)
    motions = Motions.from_poses(T_wa_a, T_board_cam, labels)
    handeye_io.check_units(motions, path, names=(PREFIX, "camera"))
    shape = "robot-eye-to-hand" if eye_to_hand else "robot-eye-in-hand"
    source = Source(
        path,
        shape,
        camera=art.ref,
        board=f"{board.name}@{board.revision}",
        image_sha256=tuple(hashes),
        skipped=tuple(skipped),
        gauge=gauge_gate(art, failures),
    )
    result = solve_result(
        motions,
        parent_frame,
        child_frame,
        method,
        thresholds(settings, lever_arm_sigma_min),
        settings,
        source,
    )
    return _write_outputs(result, outputs or Outputs())
