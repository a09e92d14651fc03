"""Solve, gate, and decide: the one call a workflow makes for a camera-IMU calibration.

``calibrate`` runs the joint estimator (``core.imu.solve``) and the gates (``core.imu.gates``). When
the (td, rotation) correlation gate or the td sigma gate fails, the motion did not pin td (smooth
constant-rate motion, seed chapter 3): with ``fallback_td_s`` given (a hardware-triggered rig knows
td = 0; a stored calibration knows its td) it solves again with td held there and estimates the
extrinsic alone, and says so (``held``, ``held_reason``); without it the verdict is a refusal. td is
the one held, never the rotation: the rotation is what the robot needs, and a td from a trigger or an
earlier calibration is a better prior than any extrinsic the degenerate data would leave. A rate
cross-correlation that cannot pin td at all (no rate variation) is the same refusal, before any solve.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from calibctl.core.gate import GateResult
from calibctl.core.imu import gates
from calibctl.core.imu.plain import TdUnobservableError, board_track
from calibctl.core.imu.samples import CameraFrames, ImuNoise, ImuSamples
from calibctl.core.imu.solve import ImuCameraSolution, SolveOptions, solve_imu_camera


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
) -> Calibration:
    """Solve and gate (module docstring).

    Raises:
        ImuInputError / ImuUnitError: the recording cannot be used as it is (the message names the fix).
    """
    track = board_track(frames)
    recording = [
        gates.rotational_excitation(track),
        gates.saturation(imu),
        gates.imu_gaps(imu),
        gates.dropped_frames(frames),
    ]
    try:
        solution = solve_imu_camera(imu, frames, noise, options, track=track)
    except TdUnobservableError as exc:
        rate = gates.rate_variation_refused(str(exc))
        if fallback_td_s is None:
            return Calibration(None, [*recording, gates.td_observability(frames), rate], None, None)
        held = solve_imu_camera(imu, frames, noise, replace(options, hold_td_s=fallback_td_s), track=track)
        reason = f"{exc}: td held at {1e3 * fallback_td_s:.3f} ms, the extrinsic estimated alone"
        free = replace(rate, gate="td_rotation_correlation_free")
        observability = gates.td_observability(frames, held.td_crlb_ms)
        return Calibration(
            held,
            [
                *recording,
                observability,
                free,
                gates.td_rotation_correlation(held.covariance_7, True),
                gates.td_sigma(held.sigma_td_ms, True),
            ],
            "td",
            reason,
        )
    recording.append(gates.td_observability(frames, solution.td_crlb_ms))
    correlation = gates.td_rotation_correlation(solution.covariance_7, solution.td_held)
    sigma = gates.td_sigma(solution.sigma_td_ms, solution.td_held)
    if (correlation.passed and sigma.passed) or fallback_td_s is None:
        return Calibration(solution, [*recording, correlation, sigma], None, None)
    held = solve_imu_camera(
        imu, frames, noise, replace(options, hold_td_s=fallback_td_s), track=track, plain=solution.plain
    )
    failed = correlation if not correlation.passed else sigma
    reason = f"{failed.message}: td held at {1e3 * fallback_td_s:.3f} ms, the extrinsic estimated alone"
    return Calibration(
        held,
        [
            *recording,
            replace(correlation, gate="td_rotation_correlation_free"),
            replace(sigma, gate="td_sigma_free"),
            gates.td_rotation_correlation(held.covariance_7, True),
            gates.td_sigma(held.sigma_td_ms, True),
        ],
        "td",
        reason,
    )
