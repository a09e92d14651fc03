"""``calibctl handeye`` as one workflow call: the rig target checked (``--rig``, exit 2 before any solve),
the solve (a motions/poses log, or a robot arm with board images: ``--images``/``--serial``), the files
(``-o``, ``--tf-static``) and the result stored as the rig's next version (rig_handeye)."""

from __future__ import annotations

from pathlib import Path

from calibctl.config import Settings
from calibctl.workflows.handeye import rig_handeye
from calibctl.workflows.handeye.handeye import HandEyeOutcome, Outputs, run_handeye


def run_handeye_command(
    settings: Settings,
    motions: Path,
    from_frame: str,
    to_frame: str,
    *,
    rig: str | None = None,
    images: Path | None = None,
    serial: str | None = None,
    board_ref: str | None = None,
    eye_to_hand: bool = False,
    shape: str = "poses",
    method: str = "park",
    max_skew_s: float = 5e-3,
    lever_arm_sigma_min: float | None = None,
    outputs: Outputs | None = None,
) -> HandEyeOutcome:
    """The whole command (module docstring); ``outcome.stored`` is the rig version written."""
    if rig is not None:
        rig_handeye.check_target(settings, rig, from_frame, to_frame, serial)
    if images is not None or serial is not None:
        from calibctl.workflows.handeye import handeye_robot

        outcome = handeye_robot.run_robot_handeye(
            settings,
            motions,
            images,
            serial,
            from_frame,
            to_frame,
            board_ref=board_ref,
            eye_to_hand=eye_to_hand,
            method=method,
            lever_arm_sigma_min=lever_arm_sigma_min,
            outputs=outputs,
        )
    else:
        outcome = run_handeye(
            settings,
            motions,
            from_frame,
            to_frame,
            shape=shape,
            method=method,
            max_skew_s=max_skew_s,
            lever_arm_sigma_min=lever_arm_sigma_min,
            outputs=outputs,
        )
    if rig is not None:
        outcome.stored = rig_handeye.store_handeye(settings, rig, outcome.result).calibration
    return outcome
