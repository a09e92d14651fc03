"""calibctl handeye and synth-motions: gates first, then the solve, then one result document.

The observability gates (rotation axes, lever arm, time alignment) run on the motions before any
solve; when one fails the result is ``rejected``, carries no transform, and the command exits 1.
Otherwise the closed form (Park & Martin or Tsai-Lenz) is refined jointly; the consistency gate
(rotation residual) and the translation-scale gate (both sensors' translations in one unit) decide
whether it is reported, with its one-sigma. The document is written with ``-o`` and, only when
accepted, as /tf_static YAML.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from calibctl import __version__, files
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.handeye import (
    FRAME_PATTERN,
    EdgeGate,
    EdgeProvenance,
    EdgeUncertainty,
    HandEyeResult,
    MotionResidual,
    RigidTransform,
)
from calibctl.artifacts.rig import RigCalibration
from calibctl.config import Settings
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.handeye import METHODS, Motions
from calibctl.core.extrinsics.handeye_gates import (
    HandEyeThresholds,
    angle_mismatch_deg,
    consistency_gate,
    evaluate_handeye_gates,
    outlier_motions,
    translation_scale_gate,
)
from calibctl.core.extrinsics.handeye_refine import HandEyeFit, fit_handeye
from calibctl.core.extrinsics.motion_synth import EXCITATIONS, synthesize_motions, synthesize_pose_log
from calibctl.core.gate import GateResult
from calibctl.errors import AlreadyExistsError, InputError, NumericalError, UsageError
from calibctl.workflows.edges.kinds import handeye_tf_yaml
from calibctl.workflows.handeye import handeye_io

UNSEALED = "0" * 64
SHAPES = ("poses", "motions")


@dataclass(frozen=True)
class Outputs:
    """Where to write the result: the JSON document and/or a /tf_static YAML (accepted results only)."""

    result_json: Path | None = None
    tf_static: Path | None = None
    force: bool = False


@dataclass
class HandEyeOutcome:
    result: HandEyeResult
    written: list[str] = field(default_factory=list)
    not_written: list[str] = field(default_factory=list)
    stored: RigCalibration | None = None  # the rig version written (``--rig``: handeye_run)

    @property
    def accepted(self) -> bool:
        return self.result.status == "accepted"


@dataclass(frozen=True)
class Source:
    """Where the motions came from, for the provenance."""

    path: Path
    shape: str
    camera: str | None = None
    board: str | None = None
    image_sha256: tuple[str, ...] = ()
    skipped: tuple[str, ...] = ()
    gauge: GateResult | None = None  # metric-gauge of the board revision (handeye_robot.gauge_gate)


def thresholds(settings: Settings, lever_arm_sigma_min: float | None = None) -> HandEyeThresholds:
    cfg = settings.handeye
    return HandEyeThresholds(
        lever_arm_sigma_min if lever_arm_sigma_min is not None else cfg.lever_arm_sigma_min,
        cfg.second_axis_min_deg,
        cfg.angle_mismatch_max_deg,
        cfg.mismatch_fraction_max,
        cfg.rotation_residual_max_deg,
        cfg.translation_scale_tolerance,
    )


def check_frames(parent_frame: str, child_frame: str) -> None:
    for name in (parent_frame, child_frame):
        if not re.match(FRAME_PATTERN, name):
            raise UsageError(
                f"'{name}' is not a frame name", "use letters, digits and _ . / - (a tf frame id)"
            )
    if parent_frame == child_frame:
        raise UsageError(f"--from and --to are both '{parent_frame}'", "name the two sensors' frames")


def _sha256_file(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from exc


def _motion_rows(motions: Motions, fit: HandEyeFit | None) -> tuple[list[MotionResidual], list[str]]:
    angle_a = np.degrees(np.linalg.norm(motions.rotvec_A_rad, axis=1))
    angle_b = np.degrees(np.linalg.norm(motions.rotvec_B_rad, axis=1))
    mismatch = angle_mismatch_deg(motions)
    flags = outlier_motions(fit) if fit is not None else np.zeros(motions.n, dtype=bool)
    rows = []
    for i, label in enumerate(motions.labels):
        rot = None if fit is None else float(np.degrees(np.linalg.norm(fit.residual_rotation_rad[i])))
        trans = None if fit is None else float(np.linalg.norm(fit.residual_translation_m[i]) * 1e3)
        rows.append(
            MotionResidual(
                label=label,
                angle_parent_deg=float(angle_a[i]),
                angle_child_deg=float(angle_b[i]),
                angle_mismatch_deg=float(mismatch[i]),
                residual_rotation_deg=rot,
                residual_translation_mm=trans,
                outlier=bool(flags[i]),
            )
        )
    return rows, [motions.labels[i] for i in np.flatnonzero(flags)]


def _uncertainty(fit: HandEyeFit) -> EdgeUncertainty | None:
    if (
        fit.covariance is None
        or fit.sigma_rotation_deg is None
        or fit.sigma_translation_m is None
        or not np.isfinite(fit.covariance).all()
    ):
        return None
    r, t = fit.sigma_rotation_deg, fit.sigma_translation_m * 1e3
    return EdgeUncertainty(
        sigma_rotation_deg=(float(r[0]), float(r[1]), float(r[2])),
        sigma_translation_mm=(float(t[0]), float(t[1]), float(t[2])),
        covariance=fit.covariance.tolist(),
        residual_rotation_deg=float(np.degrees(fit.sigma_residual_rotation_rad)),
        residual_translation_mm=float(fit.sigma_residual_translation_m * 1e3),
    )


def solve_result(
    motions: Motions,
    parent_frame: str,
    child_frame: str,
    method: str,
    th: HandEyeThresholds,
    settings: Settings,
    source: Source,
) -> HandEyeResult:
    """Gates, then (only when they all pass) the solve; the sealed result document."""
    if method not in METHODS:
        raise UsageError(f"unknown method '{method}'", f"choose one of {', '.join(METHODS)}")
    # a robot arm's photos are taken at rest: a time offset is not the cause of a mismatch there
    gates = evaluate_handeye_gates(motions, th, static_poses=source.shape.startswith("robot-"))
    if source.gauge is not None:  # a board whose gauge failed scales every translation: nothing to solve
        gates = (source.gauge, *gates)
    fit = fit_handeye(motions, method) if all(g.passed for g in gates) else None
    if fit is not None and not np.isfinite(fit.T_a_b).all():
        raise NumericalError(
            "the hand-eye refinement diverged (non-finite transform)",
            "check the motions for gross errors; one bad row can be found in the motions table",
        )
    if fit is not None:
        gates = (*gates, consistency_gate(fit, th))
        if gates[-1].passed:  # a rotation no single X explains leaves nothing to judge the translations by
            gates = (
                *gates,
                translation_scale_gate(
                    motions, fit, (parent_frame, child_frame), th.translation_scale_tolerance
                ),
            )
    accepted = all(g.passed for g in gates)
    rows, outliers = _motion_rows(motions, fit)
    transform = None
    if fit is not None and accepted:
        q = se3.quaternion_from_rotation(fit.T_a_b[:3, :3])
        t = fit.T_a_b[:3, 3]
        transform = RigidTransform(
            translation_m=(float(t[0]), float(t[1]), float(t[2])),
            rotation_wxyz=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        )
    s = np.linalg.svd((motions.R_A - np.eye(3)).reshape(-1, 3), compute_uv=False)
    provenance = EdgeProvenance(
        calibctl_version=__version__,
        opencv_version=cv2.__version__,
        station=settings.station,
        operator=settings.operator,
        created_at=utc_now(),
        input_file=source.path.name,
        input_sha256=_sha256_file(source.path),
        input_shape=source.shape,
        camera=source.camera,
        board=source.board,
        input_image_sha256=list(source.image_sha256),
    )
    result = HandEyeResult(
        parent_frame=parent_frame,
        child_frame=child_frame,
        status="accepted" if accepted else "rejected",
        method=method,
        transform=transform,
        refinement=None if fit is None else fit.model,
        uncertainty=None if fit is None or not accepted else _uncertainty(fit),
        uncertainty_refused_reason=None if fit is None or not accepted else fit.refused_reason,
        gates=[
            EdgeGate(
                gate=g.gate,
                passed=g.passed,
                value=g.value,
                threshold=g.threshold,
                message=g.message,
                hint=g.hint,
                detail=g.detail,
            )
            for g in gates
        ],
        lever_arm_singular_values=(float(s[0]), float(s[1]), float(s[2])),
        motions=rows,
        outlier_motions=outliers,
        skipped=list(source.skipped),
        provenance=provenance,
        content_sha256=UNSEALED,
    )
    return result.sealed()


def write_outputs(result: HandEyeResult, outputs: Outputs) -> HandEyeOutcome:
    outcome = HandEyeOutcome(result)
    if outputs.result_json is not None:
        files.write_atomic(outputs.result_json, result.model_dump_json(indent=2) + "\n", force=outputs.force)
        outcome.written.append(str(outputs.result_json))
    if outputs.tf_static is not None:
        if result.status == "accepted":
            files.write_atomic(outputs.tf_static, handeye_tf_yaml(result), force=outputs.force)
            outcome.written.append(str(outputs.tf_static))
        else:
            outcome.not_written.append(f"{outputs.tf_static} (rejected: no transform is published)")
    return outcome


def run_handeye(
    settings: Settings,
    path: Path,
    parent_frame: str,
    child_frame: str,
    *,
    shape: str = "poses",
    method: str = "park",
    max_skew_s: float = 0.005,
    lever_arm_sigma_min: float | None = None,
    outputs: Outputs | None = None,
) -> HandEyeOutcome:
    """Generic sensors: a motions/poses CSV (see handeye_io) -> gated, solved, written."""
    check_frames(parent_frame, child_frame)
    if shape not in SHAPES:
        raise UsageError(f"unknown --input '{shape}'", f"choose one of {', '.join(SHAPES)}")
    motions, _, _ = handeye_io.read_motions(path, shape, max_skew_s)
    result = solve_result(
        motions,
        parent_frame,
        child_frame,
        method,
        thresholds(settings, lever_arm_sigma_min),
        settings,
        Source(path, shape),
    )
    return write_outputs(result, outputs or Outputs())


MAX_SYNTH_MOTION_ROWS = 100_000  # 1000x a real hand-eye log; --rows 10^9 had no bound
MAX_SYNTH_NUMBER = 1e6  # deg, m, s, Hz: beyond this a synthetic log is nonsense (and 1e308 overflows)


@dataclass(frozen=True)
class SynthRequest:
    out: Path
    shape: str = "poses"
    n: int = 30
    excitation: str = "3d"
    amplitude_deg: float = 45.0
    noise_rotation_deg: float = 0.05
    noise_translation_m: float = 0.002
    time_offset_s: float = 0.0
    rate_hz: float = 2.0
    translation_m: tuple[float, float, float] = (0.12, -0.05, 0.30)
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 90.0)
    seed: int = 0
    force: bool = False


def run_synth_motions(request: SynthRequest) -> dict:
    """Write a motions CSV with a known X and its truth (OUT.truth.json); returns what was written."""
    if request.shape not in SHAPES:
        raise UsageError(f"unknown --shape '{request.shape}'", f"choose one of {', '.join(SHAPES)}")
    if request.excitation not in EXCITATIONS:
        raise UsageError(
            f"unknown --excitation '{request.excitation}'", f"choose one of {', '.join(EXCITATIONS)}"
        )
    if not 2 <= request.n <= MAX_SYNTH_MOTION_ROWS:
        raise UsageError(
            f"--rows {request.n} is out of range (2 .. {MAX_SYNTH_MOTION_ROWS})",
            "a hand-eye log needs tens to hundreds of motions",
        )
    numbers = (
        request.amplitude_deg,
        request.noise_rotation_deg,
        request.noise_translation_m,
        request.time_offset_s,
        request.rate_hz,
        *request.translation_m,
        *request.rotation_deg,
    )
    if not all(math.isfinite(v) and abs(v) <= MAX_SYNTH_NUMBER for v in numbers):
        raise UsageError(
            f"synth-motions needs finite numbers of at most {MAX_SYNTH_NUMBER:g}, got "
            f"{', '.join(f'{v:g}' for v in numbers if not (math.isfinite(v) and abs(v) <= MAX_SYNTH_NUMBER))}"
        )
    if request.time_offset_s and request.shape == "motions":
        raise UsageError("a time offset needs a pose log in time", "use --shape poses with --time-offset-ms")
    T_a_b = se3.transform(
        se3.rotation_from_rotvec(np.radians(request.rotation_deg)), np.array(request.translation_m)
    )
    r = request
    if r.shape == "poses":
        log = synthesize_pose_log(
            T_a_b,
            r.n,
            excitation=r.excitation,
            amplitude_deg=r.amplitude_deg,
            rate_hz=r.rate_hz,
            noise_rotation_deg=r.noise_rotation_deg,
            noise_translation_m=r.noise_translation_m,
            time_offset_s=r.time_offset_s,
            seed=r.seed,
        )
    else:
        log = synthesize_motions(
            T_a_b,
            r.n,
            excitation=r.excitation,
            amplitude_deg=r.amplitude_deg,
            noise_rotation_deg=r.noise_rotation_deg,
            noise_translation_m=r.noise_translation_m,
            seed=r.seed,
        )
    truth_path = request.out.with_name(request.out.stem + ".truth.json")
    q = se3.quaternion_from_rotation(T_a_b[:3, :3])
    truth = {
        "schema": "calibctl.synth-motions.truth/1",
        "T_a_b": T_a_b.tolist(),
        "translation_m": T_a_b[:3, 3].tolist(),
        "rotation_wxyz": q.tolist(),
        "rotation_rotvec_deg": list(request.rotation_deg),
        "shape": request.shape,
        "rows": request.n,
        "excitation": request.excitation,
        "amplitude_deg": request.amplitude_deg,
        "noise_rotation_deg": request.noise_rotation_deg,
        "noise_translation_m": request.noise_translation_m,
        "time_offset_s": request.time_offset_s,
        "rate_hz": request.rate_hz,
        "seed": request.seed,
    }
    if truth_path.exists() and not request.force:  # checked first so neither file is written
        raise AlreadyExistsError(f"{truth_path} exists", "pass --force to overwrite it")
    handeye_io.write_motion_log(request.out, log.t_s, log.T_first, log.T_second, force=request.force)
    files.write_atomic(truth_path, json.dumps(truth, indent=2, allow_nan=False) + "\n", force=request.force)
    return {
        "schema": "calibctl.synth-motions/1",
        "verdict": "pass",
        "files": {"motions": str(request.out), "truth": str(truth_path)},
        **{k: v for k, v in truth.items() if k != "schema"},
    }
