"""With model-misfit failed, the rules whose numbers follow from the misfit point at its fix, not their own."""

from __future__ import annotations

import numpy as np

from calibctl.config import LintThresholds
from calibctl.workflows.lint.lint import CalibrationFacts, lint_facts

K = np.array([[400.0, 0.0, 320.0], [0.0, 400.0, 240.0], [0.0, 0.0, 1.0]])


def _facts(fit_rms_px: float, detector_rms_px: float) -> CalibrationFacts:
    """k1k2 on a fisheye: sigma(fx) large, the outer ring worse held out, a polynomial that folds over."""
    return CalibrationFacts(
        source="t", kind="calibctl", image_size=(640, 480), camera_matrix=K,
        dist_coeffs=np.array([-0.5, 0.0, 0.0, 0.0, 0.0]), sigma_fx_px=3.1, fit_outer_rms_px=3.0,
        held_out_outer_rms_px=4.0, square_size_status="measured", model_name="k1k2",
        fit_rms_px=fit_rms_px, detector_rms_px=detector_rms_px)


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
