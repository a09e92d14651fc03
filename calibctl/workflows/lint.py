"""calibctl lint: the gate CI runs on every calibration file (seed chapter 1, 'the calibration lint').

Inputs are calibctl artifacts (JSON/YAML), ROS camera_info YAML, or artifacts in the store. Each rule
has an id, a severity, a message with the numbers and the fix. Numeric rules live in
``calibctl.core.lens_checks`` (pure numpy) so the solve applies exactly the same checks.

A file that is not a calibration at all, or cannot be read, is an InputError (exit 2); a calibration
that breaks a rule is a finding (exit 1 when any finding is an error).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import validation_message
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.config import LintThresholds, Settings
from calibctl.core import lens_checks
from calibctl.errors import InputError, UsageError
from calibctl.workflows import formats


@dataclass
class CalibrationFacts:
    """What lint needs, extracted the same way from every input format."""

    source: str
    kind: str  # "calibctl" or "ros"
    image_size: tuple[int, int] | None
    camera_matrix: np.ndarray  # (3, 3)
    dist_coeffs: np.ndarray  # (N,)
    sigma_fx_px: float | None = None
    sigma_refused_reason: str | None = None
    fit_outer_rms_px: float | None = None
    held_out_outer_rms_px: float | None = None
    square_size_status: str | None = None  # measured | nominal | None (not recorded)
    square_size_m: float | None = None
    camera_consistency: dict[str, Any] | None = None  # the solve's two-camera check, calibctl artifacts only
    raw_numbers: list[float] = field(default_factory=list)


@dataclass
class LintResult:
    source: str
    kind: str
    findings: list[Finding]

    @property
    def failed(self) -> bool:
        return has_errors(self.findings)

    def as_json(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "kind": self.kind,
            "verdict": "fail" if self.failed else "pass",
            "errors": sum(f.severity == "error" for f in self.findings),
            "warnings": sum(f.severity == "warning" for f in self.findings),
            "findings": [f.model_dump(mode="json") for f in self.findings],
        }


def _numbers(obj: Any) -> list[float]:
    if isinstance(obj, bool):
        return []
    if isinstance(obj, int | float):
        return [float(obj)]
    if isinstance(obj, dict):
        return [x for v in obj.values() for x in _numbers(v)]
    if isinstance(obj, list | tuple):
        return [x for v in obj for x in _numbers(v)]
    return []


def _matrix(value: Any, shape: tuple[int, ...], source: str, name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(shape)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{source}: {name} is not a {'x'.join(map(str, shape))} array of numbers") from exc
    return arr


def _ros_facts(data: dict[str, Any], source: str) -> CalibrationFacts:
    k = data["camera_matrix"]
    dist = data.get("distortion_coefficients") or {"data": []}
    w, h = data.get("image_width"), data.get("image_height")
    size = (int(w), int(h)) if isinstance(w, int) and isinstance(h, int) else None
    return CalibrationFacts(
        source=source,
        kind="ros",
        image_size=size,
        camera_matrix=_matrix(k.get("data") if isinstance(k, dict) else k, (3, 3), source, "camera_matrix"),
        dist_coeffs=_matrix(dist.get("data", []) if isinstance(dist, dict) else dist, (-1,), source, "distortion"),
        raw_numbers=_numbers(data),
    )


def _calibctl_facts(data: dict[str, Any], source: str) -> CalibrationFacts:
    size = data.get("image_size")
    stdev = data.get("stdev") or {}
    held = data.get("held_out") or {}
    measurement = (data.get("board") or {}).get("measurement") or {}
    sigma_fx = (stdev.get("sigma") or {}).get("fx")
    return CalibrationFacts(
        source=source,
        kind="calibctl",
        image_size=(int(size[0]), int(size[1])) if isinstance(size, list | tuple) and len(size) == 2 else None,
        camera_matrix=_matrix(data["camera_matrix"], (3, 3), source, "camera_matrix"),
        dist_coeffs=_matrix(data.get("dist_coeffs", []), (-1,), source, "dist_coeffs"),
        sigma_fx_px=float(sigma_fx) if isinstance(sigma_fx, int | float) else None,
        sigma_refused_reason=stdev.get("refused_reason"),
        fit_outer_rms_px=held.get("fit_outer_ring_rms_px"),
        held_out_outer_rms_px=held.get("outer_ring_rms_px"),
        square_size_status=measurement.get("status"),
        square_size_m=measurement.get("square_size_m"),
        camera_consistency=data.get("camera_consistency"),
        raw_numbers=_numbers(data),
    )


def facts_from_document(data: Any, source: str) -> CalibrationFacts:
    """Recognise the format; anything that is not a calibration is an InputError (exit 2)."""
    if formats.looks_like_artifact(data):
        return _calibctl_facts(data, source)
    if isinstance(data, dict) and "camera_matrix" in data and ("image_width" in data or "distortion_model" in data):
        return _ros_facts(data, source)
    raise InputError(
        f"{source} is not a calibration (neither a calibctl artifact nor ROS camera_info YAML)",
        "lint takes files written by `calibctl export` or ROS camera_calibration",
    )


def _document_rules(data: dict[str, Any], source: str) -> list[Finding]:
    """Schema and hash rules, calibctl artifacts only."""
    try:
        art = CalibrationArtifact.model_validate(data)
    except ValidationError as exc:
        return [
            Finding(
                rule="schema",
                severity="error",
                message=validation_message(exc, source),
                fix="re-export the artifact from the store; never edit one by hand",
            )
        ]
    actual = art.computed_sha256()
    if actual != art.content_sha256:
        return [
            Finding(
                rule="content-hash",
                severity="error",
                message=f"content sha256 is {actual[:12]} but the file records {art.content_sha256[:12]}: "
                "it was changed after it was written",
                fix="re-export it from the store",
            )
        ]
    return []


def _provenance_rule(facts: CalibrationFacts) -> list[Finding]:
    if facts.square_size_status == "measured":
        return []
    if facts.square_size_status == "nominal":
        mm = f"{facts.square_size_m * 1000:.3f} mm " if facts.square_size_m else ""
        message = f"square size {mm}is nominal (typed, never measured): every metric output scales with it"
    else:
        message = "no square-size provenance recorded: the metric gauge of this calibration cannot be audited"
    return [
        Finding(
            rule="square-size-provenance",
            severity="error",
            message=message,
            fix="measure the squares (calipers), `calibctl board add NAME --square-mm ... --uncertainty-mm ... "
            "--instrument ... --measured-by ... --measured-on ...`, and recalibrate",
        )
    ]


def _adopt(check: lens_checks.Finding) -> list[Finding]:
    """A failed core check becomes a finding; a passed one is not reported."""
    if check.passed:
        return []
    return [Finding(rule=check.rule, severity=check.severity, message=check.message, fix=check.fix)]


def _outer_ring_rule(facts: CalibrationFacts, limits: LintThresholds) -> list[Finding]:
    if facts.fit_outer_rms_px is None or facts.held_out_outer_rms_px is None:
        return [
            Finding(
                rule="outer-ring-holdout",
                severity="error",
                message="no held-out outer-ring error recorded: an over-fitted distortion model would pass unseen",
                fix="recalibrate with calibctl solve (k-fold held-out validation)",
                threshold=limits.outer_ring_ratio_max,
            )
        ]
    return _adopt(
        lens_checks.check_outer_ring_holdout(
            facts.held_out_outer_rms_px, facts.fit_outer_rms_px, limits.outer_ring_ratio_max
        )
    )


def _one_camera_rule(facts: CalibrationFacts) -> list[Finding]:
    check = facts.camera_consistency
    if not check or not check.get("two_cameras_suspected"):
        return []
    a, b = check["group_a"], check["group_b"]
    held, cross = check["holdout_rms_px"], check["cross_rms_px"]

    def group(names: list[str], k: int) -> str:
        shown = ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")
        return (f"{len(names)} views ({shown}; fx {check['fx_px'][k]:.1f}, cx {check['cx_px'][k]:.1f}, "
                f"cy {check['cy_px'][k]:.1f} px alone)")

    return [Finding(
        rule="one-camera", severity="error", value=check["ratio"], threshold=check["threshold"],
        message=f"the views disagree the way two cameras would: {group(a, 0)} and {group(b, 1)}; each group is "
        f"predicted {cross[0] / held[0]:.2f}x and {cross[1] / held[1]:.2f}x worse by the other's camera than by "
        f"its own (held-out {held[0]:.3f} / {held[1]:.3f} px); this calibration is a blend",
        fix="calibrate each camera from its own images (e.g. --source 'left*.jpg'); if it is one camera, "
        "check that nothing moved (focus, zoom, lens) during the capture")]


def lint_facts(facts: CalibrationFacts, limits: LintThresholds) -> list[Finding]:
    """Every rule that applies to one calibration, in a stable order."""
    bad = [x for x in facts.raw_numbers if not math.isfinite(x)]
    if bad:
        return [
            Finding(
                rule="finite",
                severity="error",
                message=f"{len(bad)} value(s) are NaN or infinite",
                fix="this file does not describe a camera; recalibrate",
            )
        ]
    K, size = facts.camera_matrix, facts.image_size
    findings = _adopt(lens_checks.check_image_size(size, K))
    if size is not None and not findings:
        findings += _adopt(lens_checks.check_principal_point(K, size, limits.principal_point_max_frac))
    findings += _adopt(lens_checks.check_sigma_fx(facts.sigma_fx_px, facts.sigma_refused_reason, limits.sigma_fx_max_px))
    findings += _outer_ring_rule(facts, limits)
    findings += _provenance_rule(facts)
    findings += _one_camera_rule(facts)
    findings += _adopt(lens_checks.check_aspect_ratio(K, limits.aspect_max_frac))
    if size is not None and facts.dist_coeffs.size:
        findings += _adopt(lens_checks.check_distortion_foldover(K, facts.dist_coeffs, size))
    return findings


def lint_document(data: Any, source: str, limits: LintThresholds) -> LintResult:
    facts = facts_from_document(data, source)
    findings = _document_rules(data, source) if facts.kind == "calibctl" else []
    findings += lint_facts(facts, limits)
    return LintResult(source=source, kind=facts.kind, findings=findings)


def lint_files(paths: list[Path], limits: LintThresholds) -> list[LintResult]:
    return [lint_document(formats.load_structured_file(p), str(p), limits) for p in paths]


def lint_store(settings: Settings, serial: str | None, all_serials: bool) -> list[LintResult]:
    """Lint the active version of one serial, or of every serial in the store."""
    from calibctl.workflows.records import open_store

    with open_store(settings) as store:
        serials = store.serials() if all_serials else [serial] if serial else []
        results = []
        for s in serials:
            art = store.get_artifact(s, None)
            data = art.model_dump(mode="json")
            results.append(lint_document(data, art.ref, settings.lint))
    return results


def lint(settings: Settings, paths: list[Path], serial: str | None, all_serials: bool) -> list[LintResult]:
    if not paths and not serial and not all_serials:
        raise UsageError("nothing to lint", "name files, or pass --serial SERIAL or --all")
    results = lint_files(paths, settings.lint)
    if serial or all_serials:
        results += lint_store(settings, serial, all_serials)
    return results
