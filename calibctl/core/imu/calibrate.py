"""Solve, gate, and decide: the one call a workflow makes for a camera-IMU calibration.

``calibrate`` runs the joint estimator (``core.imu.solve``) and the gates (``core.imu.gates``). When
the (td, rotation) correlation gate or the td sigma gate fails, the motion did not pin td (smooth
constant-rate motion, seed chapter 3): with ``fallback_td_s`` given (a hardware-triggered rig knows
td = 0; a stored calibration knows its td) it solves again with td held there and estimates the
extrinsic alone, and says so (``held``, ``held_reason``); without it the verdict is a refusal. td is
the one held, never the rotation: the rotation is what the robot needs, and a td from a trigger or an
earlier calibration is a better prior than any extrinsic the degenerate data would leave. A rate
cross-correlation that cannot pin td at all (no rate variation) is the same refusal, before any solve.
An IMU model beyond ``calibrated`` (``SolveOptions.imu_model``) adds its observability gate: a recording
that cannot pin the model's states is refused, naming the model. Every solved verdict carries the
``board_scale`` gate (one more solve with the board's size as a state: the accelerometer is its metric
gauge) and each camera's ``camera_fit`` gate (its intrinsics against the IMU's turns), ``core.imu.metric``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from calibctl.core.gate import GateResult
from calibctl.core.imu import gates, metric
from calibctl.core.imu.plain import BoardTrack, TdUnobservableError, board_track, plain_calibration
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples
from calibctl.core.imu.solve import ImuCameraSolution, SolveOptions, solve_imu_cameras


@dataclass(frozen=True)
class Calibration:
    """solution: the final solve (None: refused before solving, the gates say why). gates: every gate
    on it. held: "td" when td was held after the correlation gate failed (None otherwise).
    held_reason: why, in words. passed: every gate passed (a held td passes the td gates by
    construction; the failed first try's td gates are in ``gates`` with the suffix ``_free``)."""

    solution: ImuCameraSolution | None
    gates: list[GateResult]
    held: str | None
    held_reason: str | None

    @property
    def passed(self) -> bool:
        return all(g.passed for g in self.gates if not g.gate.endswith("_free"))

    @property
    def failed(self) -> list[GateResult]:
        return [g for g in self.gates if not g.passed and not g.gate.endswith("_free")]


def calibrate(
    imu: ImuSamples,
    frames: CameraFrames,
    noise: ImuNoise,
    options: SolveOptions = SolveOptions(),
    fallback_td_s: float | None = None,
    square_mm: float | None = None,
) -> Calibration:
    """Solve and gate one camera (module docstring).

    Raises:
        ImuInputError / ImuUnitError: the recording cannot be used as it is (the message names the fix).
    """
    return calibrate_cameras(imu, [frames], noise, options, fallback_td_s, square_mm=square_mm)[0]


def calibrate_cameras(
    imu: ImuSamples,
    cameras: Sequence[CameraFrames],
    noise: ImuNoise,
    options: SolveOptions = SolveOptions(),
    fallback_td_s: float | None = None,
    rig: Sequence[np.ndarray | None] | None = None,
    square_mm: float | None = None,
) -> list[Calibration]:
    """Solve several cameras and one IMU jointly (``core.imu.solve.solve_imu_cameras``) and gate each
    camera; one ``Calibration`` per camera, in order. The IMU's gates are shared. When any camera's
    motion cannot pin its td, every camera's td is held at ``fallback_td_s`` (one rig clock) or every
    camera is refused. ``rig``: the cameras the rig already relates to the first (``solve_imu_cameras``).
    ``square_mm``: the registered board's square (tag) edge, named by the ``board_scale`` gate.

    Raises:
        ImuInputError / ImuUnitError: the recording cannot be used as it is (the message names the fix).
    """
    tracks = [board_track(f) for f in cameras]
    recording = [
        [
            gates.rotational_excitation(track),
            gates.saturation(imu),
            gates.imu_gaps(imu),
            gates.dropped_frames(frames),
        ]
        for track, frames in zip(tracks, cameras, strict=True)
    ]
    try:
        plains = [
            plain_calibration(imu, f, t, td_s=options.hold_td_s) for f, t in zip(cameras, tracks, strict=True)
        ]
    except TdUnobservableError as exc:
        rate = gates.rate_variation_refused(str(exc))
        if fallback_td_s is None:
            return [
                Calibration(None, [*rec, gates.td_observability(frames), rate], None, None)
                for rec, frames in zip(recording, cameras, strict=True)
            ]
        held = solve_imu_cameras(
            imu, cameras, noise, replace(options, hold_td_s=fallback_td_s), tracks=tracks, rig=rig
        )
        reason = f"{exc}: td held at {1e3 * fallback_td_s:.3f} ms, the extrinsic estimated alone"
        free = replace(rate, gate="td_rotation_correlation_free")
        held_options = replace(options, hold_td_s=fallback_td_s)
        _metric_gates(recording, imu, cameras, noise, held_options, tracks, held, rig, square_mm)
        return [
            Calibration(
                h,
                [
                    *rec,
                    gates.td_observability(frames, h.td_crlb_ms),
                    *rg,
                    free,
                    gates.td_rotation_correlation(h.covariance_7, True),
                    gates.td_sigma(h.sigma_td_ms, True),
                    *_model_gates(h),
                ],
                "td",
                reason,
            )
            for h, rec, frames, rg in zip(
                held, recording, cameras, _rig_gates(cameras, tracks, held, rig), strict=True
            )
        ]
    solutions = solve_imu_cameras(imu, cameras, noise, options, tracks, plains, rig)
    for rec, frames, s in zip(recording, cameras, solutions, strict=True):
        rec.append(gates.td_observability(frames, s.td_crlb_ms))
    correlation = [gates.td_rotation_correlation(s.covariance_7, s.td_held) for s in solutions]
    sigma = [gates.td_sigma(s.sigma_td_ms, s.td_held) for s in solutions]
    failed = [g for pair in zip(correlation, sigma, strict=True) for g in pair if not g.passed]
    if not failed or fallback_td_s is None:
        _metric_gates(recording, imu, cameras, noise, options, tracks, solutions, rig, square_mm)
        return [
            Calibration(s, [*rec, *rg, corr, sig, *_model_gates(s)], None, None)
            for s, rec, rg, corr, sig in zip(
                solutions,
                recording,
                _rig_gates(cameras, tracks, solutions, rig),
                correlation,
                sigma,
                strict=True,
            )
        ]
    held = solve_imu_cameras(
        imu,
        cameras,
        noise,
        replace(options, hold_td_s=fallback_td_s),
        tracks,
        [s.plain for s in solutions],
        rig,
    )
    reason = f"{failed[0].message}: td held at {1e3 * fallback_td_s:.3f} ms, the extrinsic estimated alone"
    # The rig gate judges the reported (held) solution's corners, not the free solve's.
    held_options = replace(options, hold_td_s=fallback_td_s)
    _metric_gates(recording, imu, cameras, noise, held_options, tracks, held, rig, square_mm)
    return [
        Calibration(
            h,
            [
                *rec,
                *rg,
                replace(corr, gate="td_rotation_correlation_free"),
                replace(sig, gate="td_sigma_free"),
                gates.td_rotation_correlation(h.covariance_7, True),
                gates.td_sigma(h.sigma_td_ms, True),
                *_model_gates(h),
            ],
            "td",
            reason,
        )
        for h, rec, rg, corr, sig in zip(
            held, recording, _rig_gates(cameras, tracks, held, rig), correlation, sigma, strict=True
        )
    ]


def _model_gates(s: ImuCameraSolution) -> list[GateResult]:
    """The IMU model's observability gate, when the solve estimated a model beyond ``calibrated``."""
    m = s.imu_intrinsics
    return [] if m is None else [gates.imu_model_observability(m.model, m.min_information)]


def _rig_gates(
    cameras: Sequence[CameraFrames],
    tracks: Sequence[BoardTrack],
    solutions: Sequence[ImuCameraSolution],
    rig: Sequence[np.ndarray | None] | None,
) -> list[list[GateResult]]:
    """Per camera, the ``rig_pose`` gates on ``solutions`` (the ones reported): every camera held through
    the rig's pose gets its own, and the first camera a copy (the held camera's corners pin the first
    camera's extrinsic)."""
    out: list[list[GateResult]] = [[] for _ in cameras]
    for k, (frames, track, s) in enumerate(zip(cameras, tracks, solutions, strict=True)):
        if rig is not None and rig[k] is not None:
            gate = gates.rig_pose(s.corner_rms_px, gates.pnp_rms_px(frames, track))
            out[k].append(gate)
            out[0].append(replace(gate, gate=f"rig_pose_camera_{k}"))
    return out


def _metric_gates(
    recording: list[list[GateResult]],
    imu: ImuSamples,
    cameras: Sequence[CameraFrames],
    noise: ImuNoise,
    options: SolveOptions,
    tracks: Sequence[BoardTrack],
    solutions: Sequence[ImuCameraSolution],
    rig: Sequence[np.ndarray | None] | None,
    square_mm: float | None,
) -> None:
    """The ``board_scale`` gate (one board: one more joint solve, shared by every camera) and each
    camera's ``camera_fit`` gate, appended to its gates (``core.imu.metric``)."""
    scale = gates.board_scale(
        metric.board_scale(
            imu, cameras, noise, options, tracks, solutions, rig, refusable=gates.MIN_SCALE_ERROR
        ),
        square_mm,
    )
    for rec, frames, track, s in zip(recording, cameras, tracks, solutions, strict=True):
        rec += [scale, gates.camera_fit(metric.camera_fit(frames, track, s))]
