"""Camera-IMU gates: a good dance passes; the corridor (constant rate about one axis) is refused, or held
and named, and never reported with a small sigma."""

from __future__ import annotations

from calibctl.core.imu.calibrate import Calibration, calibrate
from calibctl.core.imu.solve import SolveOptions
from calibctl.core.synth.imu import ImuCameraRecording, synthesize_imu_camera
from tests.core.imu.conftest import as_inputs


def test_the_dance_passes_every_gate(dance_calibration: Calibration) -> None:
    assert dance_calibration.passed, [g.message for g in dance_calibration.failed]
    assert dance_calibration.held is None
    names = {g.gate for g in dance_calibration.gates}
    assert names >= {
        "rotational_excitation",
        "td_observability",
        "td_rotation_correlation",
        "saturation",
        "imu_gaps",
        "dropped_frames",
        "td_sigma",
        "board_scale",
        "camera_fit",
    }


def test_the_corridor_is_refused_naming_td_and_rotation(corridor: ImuCameraRecording) -> None:
    cal = calibrate(*as_inputs(corridor), SolveOptions(folds=0, jackknife_blocks=0))
    assert not cal.passed
    assert cal.solution is None
    reasons = {g.reason for g in cal.failed}
    assert "td_rotation_degenerate" in reasons and "rotation_starved" in reasons
    hint = next(g.hint for g in cal.failed if g.reason == "td_rotation_degenerate")
    assert hint is not None and "reversals" in hint and "hold td" in hint


def test_the_corridor_with_a_known_td_holds_it_and_says_so(corridor: ImuCameraRecording) -> None:
    options = SolveOptions(folds=0, jackknife_blocks=0, max_iterations=15)
    cal = calibrate(*as_inputs(corridor), options, fallback_td_s=corridor.truth.td_s)
    assert cal.held == "td" and cal.held_reason is not None and "td held" in cal.held_reason
    s = cal.solution
    assert s is not None and s.td_held and s.td_s == corridor.truth.td_s
    # One rotation axis cannot pin the extrinsic: still refused, and with a large sigma, not a small one.
    assert not cal.passed
    assert max(s.sigma_rotation_deg) > 1.0 and max(s.sigma_translation_mm) > 50.0


def test_a_corridor_whose_rate_barely_swings_leaves_td_unpinned_and_is_held_when_asked() -> None:
    # The rate swings 0.05 rad/s: the cross-correlation finds its peak, the joint solve converges, the
    # (td, rotation) correlation reads low (the rotation about the turning axis is unpinned itself),
    # and td's sigma says what the motion could not do.
    rec = synthesize_imu_camera(1, motion="corridor", duration_s=6.0, corridor_wobble_rad_s=0.05)
    options = SolveOptions(folds=0, jackknife_blocks=0, max_iterations=15)
    cal = calibrate(*as_inputs(rec), options)
    assert cal.solution is not None and not cal.passed
    assert {"td_unpinned", "rotation_starved"} <= {g.reason for g in cal.failed}
    assert cal.solution.sigma_td_ms > 0.5
    held = calibrate(*as_inputs(rec), options, fallback_td_s=rec.truth.td_s)
    assert held.held == "td" and held.held_reason is not None and "sigma td" in held.held_reason
    assert held.solution is not None and held.solution.td_held
    assert {g.gate for g in held.gates} >= {"td_sigma_free", "td_rotation_correlation_free", "td_sigma"}
