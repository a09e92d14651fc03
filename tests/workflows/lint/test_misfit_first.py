"""With model-misfit failed, the rules whose numbers follow from the misfit point at its fix, not their
own."""

from __future__ import annotations

import numpy as np

from calibctl.config import LintThresholds
from calibctl.workflows.lint.lint import CalibrationFacts, lint_facts

K = np.array([[400.0, 0.0, 320.0], [0.0, 400.0, 240.0], [0.0, 0.0, 1.0]])


def _facts(fit_rms_px: float, detector_rms_px: float) -> CalibrationFacts:
    """k1k2 on a fisheye: sigma(fx) large, the outer ring worse held out, a polynomial that folds over."""
    return CalibrationFacts(
        source="t",
        kind="calibctl",
        image_size=(640, 480),
        camera_matrix=K,
        dist_coeffs=np.array([-0.5, 0.0, 0.0, 0.0, 0.0]),
        sigma_fx_px=3.1,
        fit_outer_rms_px=3.0,
        held_out_outer_rms_px=4.0,
        square_size_status="measured",
        model_name="k1k2",
        fit_rms_px=fit_rms_px,
        detector_rms_px=detector_rms_px,
    )


def test_symptom_rules_point_at_the_misfit_fix():
    findings = {f.rule: f for f in lint_facts(_facts(2.47, 0.28), LintThresholds())}
    assert "--model fisheye" in (findings["model-misfit"].fix or "")
    for rule in ("sigma-fx", "outer-ring-holdout", "distortion-foldover"):
        assert findings[rule].severity == "error"  # the verdicts stay
        fix = findings[rule].fix or ""
        assert fix.startswith("first fix model-misfit (solve with --model fisheye")
        assert "make the corners sharp" not in fix and "--model k1k2)" not in fix


def test_without_a_misfit_each_rule_keeps_its_own_fix():
    findings = {f.rule: f for f in lint_facts(_facts(0.30, 0.28), LintThresholds())}
    assert "model-misfit" not in findings
    assert not (findings["outer-ring-holdout"].fix or "").startswith("first fix model-misfit")
    assert "--model k1k2" not in (findings["outer-ring-holdout"].fix or "")  # a k1k2 solve


K_WEBCAM = np.array([[554.0, 0.0, 320.0], [0.0, 554.0, 240.0], [0.0, 0.0, 1.0]])  # 60 deg across 640 px
DRIFT = {
    "two_cameras_suspected": True,
    "group_a": ["v1", "v2", "v3", "v4"],
    "group_b": ["v5", "v6", "v7", "v8"],
    "holdout_rms_px": [0.3, 0.3],
    "cross_rms_px": [2.4, 2.6],
    "fx_px": [548.0, 561.0],
    "cx_px": [318.0, 322.0],
    "cy_px": [239.0, 241.0],
    "ratio": 8.0,
    "threshold": 2.0,
}


def _webcam(consistency: dict | None) -> CalibrationFacts:
    """A ~60 deg webcam whose focus drifted through the session, solved k1k2: misfit (and one-camera)."""
    return CalibrationFacts(
        source="t",
        kind="calibctl",
        image_size=(640, 480),
        camera_matrix=K_WEBCAM,
        dist_coeffs=np.array([0.05, -0.1, 0.0, 0.0, 0.0]),
        sigma_fx_px=0.5,
        square_size_status="measured",
        model_name="k1k2",
        fit_rms_px=1.9,
        detector_rms_px=0.25,
        camera_consistency=consistency,
    )


def test_a_narrow_webcam_is_not_sent_to_the_fisheye_model():
    findings = {f.rule: f for f in lint_facts(_webcam(None), LintThresholds())}
    fix = findings["model-misfit"].fix or ""
    assert findings["model-misfit"].severity == "error"
    assert "--model fisheye" not in fix and "focus, zoom and autofocus" in fix and "about 83 deg" in fix


def test_a_drifting_webcam_points_the_misfit_at_one_camera():
    findings = {f.rule: f for f in lint_facts(_webcam(DRIFT), LintThresholds())}
    assert (
        findings["model-misfit"].severity == findings["one-camera"].severity == "error"
    )  # the verdicts stay
    assert (findings["model-misfit"].fix or "").startswith("first fix one-camera (calibrate each camera")
    assert "--model fisheye" not in (findings["model-misfit"].fix or "")
    assert not (findings["one-camera"].fix or "").startswith("first fix model-misfit")


CHANGED = {
    "first_view_after": "v5",
    "views": [4, 4],
    "before_px": {"fx": 548.0, "fy": 548.0, "cx": 320.0, "cy": 240.0},
    "after_px": {"fx": 556.0, "fy": 556.0, "cx": 320.5, "cy": 240.0},
    "focal_step": 0.0146,
    "centre_step_px": 0.5,
    "chi2": 90.0,
    "limit": 18.0,
    "changed": True,
}


def test_a_webcam_that_changed_points_the_misfit_and_one_camera_at_the_lens_lock():
    facts = _webcam(DRIFT)
    facts.camera_change = CHANGED
    findings = {f.rule: f for f in lint_facts(facts, LintThresholds())}
    changed = findings["camera-changed"]
    assert changed.severity == "error" and (changed.fix or "").startswith(
        "the camera changed during the session"
    )
    for rule in ("model-misfit", "one-camera"):
        assert (findings[rule].fix or "").startswith("first fix camera-changed (the camera changed")


def test_on_a_wide_lens_a_changed_camera_reading_is_a_symptom_of_the_misfit():
    facts = _facts(2.47, 0.28)
    facts.camera_change = CHANGED
    findings = {f.rule: f for f in lint_facts(facts, LintThresholds())}
    assert (findings["camera-changed"].fix or "").startswith(
        "first fix model-misfit (solve with --model fisheye"
    )
