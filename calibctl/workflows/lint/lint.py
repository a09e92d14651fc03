"""calibctl lint: the gate CI runs on every calibration file (seed chapter 1, 'the calibration lint').

Inputs are every format ``calibctl export`` writes (artifact JSON/YAML, ROS camera_info, OpenCV
FileStorage), camera_info files from ROS itself, and artifacts in the store. Each rule has an id, a
severity, a message with the numbers and the fix. ROS and OpenCV exports are checked against their
trace header (``trace_header``): an edited file is a ``content-hash`` error, a file without one is
linted on its numbers and says it cannot be traced. Numeric rules live in
``calibctl.core.intrinsics.lens_checks`` (pure numpy) so the solve applies exactly the same checks.

A file that is not a calibration at all, or cannot be read, is an InputError (exit 2); a calibration
that breaks a rule is a finding (exit 1 when any finding is an error).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import ValidationError

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import validation_message
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.config import LintThresholds, Settings
from calibctl.core.capture.image_circle import circle_from_detail
from calibctl.core.intrinsics import lens_checks, model_fit
from calibctl.core.intrinsics.camera_change import changed_hint
from calibctl.errors import InputError, NotFoundError, UnverifiedRecord, named_list
from calibctl.signing import TrustedKeys
from calibctl.workflows.board.gauge_failures import failure_fix, failure_text
from calibctl.workflows.exports import formats, ros_camera_info, trace_header
from calibctl.workflows.store_admin import keys

if TYPE_CHECKING:
    from calibctl.store.gauge_failures import GaugeFailure


@dataclass
class CalibrationFacts:
    """What lint needs, extracted the same way from every input format."""

    source: str
    kind: str  # "calibctl", "ros" or "opencv"
    image_size: tuple[int, int] | None
    camera_matrix: np.ndarray  # (3, 3)
    dist_coeffs: np.ndarray  # (N,)
    distortion_model: str = "brown-conrady"  # or "equidistant" (ROS fisheye: k1..k4)
    sigma_fx_px: float | None = None
    sigma_refused_reason: str | None = None
    fit_outer_rms_px: float | None = None
    held_out_outer_rms_px: float | None = None
    square_size_status: str | None = None  # measured | nominal | None (not recorded)
    square_size_m: float | None = None
    camera_consistency: dict[str, Any] | None = None  # the solve's two-camera check, calibctl artifacts only
    camera_change: dict[str, Any] | None = None  # the solve's changed-camera check, calibctl artifacts only
    model_name: str | None = None  # calibctl artifacts only, as the three below
    fit_rms_px: float | None = None
    detector_rms_px: float | None = None
    fit_ring_rms_px: tuple[float | None, float | None] = (None, None)  # inner and outer radius quintile
    image_circle: tuple[float, float, float] | None = (
        None  # (cx, cy, r) px from the coverage gate, calibctl only
    )
    observed_region_px: np.ndarray | None = None  # (K, 2) hull of the solve's corners, calibctl only
    required_region_px: np.ndarray | None = (
        None  # (K, 2) the station's declared region at the solve, calibctl only
    )
    metric_gauge: dict[str, Any] | None = None  # the capture's distance gauge, calibctl only
    gauge_override: str | None = None  # provenance.gauge_override: why a failed gauge was overridden
    # the store's failed gauges of the board revision (workflows.board.gauge_failures): (board ref, message)
    board_gauge: tuple[str, str] | None = None
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


def with_evidence(facts: CalibrationFacts, evidence: dict[str, Any]) -> CalibrationFacts:
    """What a trace header vouches for (sigma, held-out outer ring, square size) added to the numbers."""

    def number(key: str) -> float | None:
        value = evidence.get(key)
        return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None

    facts.sigma_fx_px = number("sigma_fx_px")
    reason = evidence.get("sigma_refused_reason")
    facts.sigma_refused_reason = reason if isinstance(reason, str) else None
    facts.fit_outer_rms_px = number("fit_outer_ring_rms_px")
    facts.held_out_outer_rms_px = number("held_out_outer_ring_rms_px")
    status = evidence.get("square_size_status")
    facts.square_size_status = status if isinstance(status, str) else None
    facts.square_size_m = number("square_size_m")
    return facts


def _ros_facts(data: dict[str, Any], source: str) -> CalibrationFacts:
    return CalibrationFacts(
        source=source,
        kind="ros",
        image_size=(data["image_width"], data["image_height"]),
        camera_matrix=_matrix(data["camera_matrix"]["data"], (3, 3), source, "camera_matrix"),
        dist_coeffs=_matrix(data["distortion_coefficients"]["data"], (-1,), source, "distortion"),
        distortion_model=_distortion_model(data.get("distortion_model")),
        raw_numbers=_numbers(data),
    )


def file_facts(loaded: formats.CalibrationFile) -> CalibrationFacts | None:
    """The facts of a ROS or OpenCV file, or None for another kind or one whose numbers cannot be read
    (``lint_file`` names why)."""
    try:
        if loaded.kind == "ros":
            return _ros_facts(loaded.data, loaded.source)
        return _opencv_facts(loaded.data, loaded.source) if loaded.kind == "opencv" else None
    except (InputError, KeyError, TypeError, ValueError):
        return None


def _distortion_model(name: Any) -> str:
    """ROS/OpenCV ``distortion_model`` or a calibctl model name -> the lint's lens family."""
    return "equidistant" if name in ("equidistant", "fisheye") else "brown-conrady"


def _opencv_facts(data: dict[str, Any], source: str) -> CalibrationFacts:
    if "camera_matrix" not in data:
        raise InputError(f"{source}: an OpenCV FileStorage file without camera_matrix is not a calibration")
    w, h = data.get("image_width"), data.get("image_height")
    return CalibrationFacts(
        source=source,
        kind="opencv",
        image_size=(w, h) if isinstance(w, int) and isinstance(h, int) else None,
        camera_matrix=_matrix(data["camera_matrix"], (3, 3), source, "camera_matrix"),
        dist_coeffs=_matrix(
            data.get("distortion_coefficients", []), (-1,), source, "distortion_coefficients"
        ),
        distortion_model=_distortion_model(data.get("distortion_model")),
        raw_numbers=_numbers(data),
    )


FACT_FIELDS: dict[str, Any] = {
    "image_size": True,
    "camera_matrix": True,
    "dist_coeffs": True,
    "model": {"name"},
    "rms_px": True,
    "detector_rms_px": True,
    "stdev": {"sigma", "refused_reason"},
    "board": {"measurement"},
    "held_out": {"fit_outer_ring_rms_px", "outer_ring_rms_px", "by_radius"},
    "camera_consistency": True,
    "camera_change": True,
    "metric_gauge": True,
    "provenance": {"gauge_override"},
    "observed_region_px": True,
    "required_region_px": True,
}
"""The parts of an artifact's dump ``facts_from_document`` reads (views, provenance, covariance are not)."""


def facts_from_document(data: dict[str, Any], source: str, *, validated: bool = False) -> CalibrationFacts:
    """The facts of a calibctl artifact document (parsed JSON/YAML or a stored artifact's dump). A
    ``validated`` document (parsed by the contract, which refuses NaN and infinity) skips the walk over
    every number that the ``finite`` rule needs for files."""
    size = data.get("image_size")
    stdev = data.get("stdev") or {}
    held = data.get("held_out") or {}
    measurement = (data.get("board") or {}).get("measurement") or {}
    sigma_fx = (stdev.get("sigma") or {}).get("fx")
    return CalibrationFacts(
        source=source,
        kind="calibctl",
        image_size=(int(size[0]), int(size[1]))
        if isinstance(size, list | tuple) and len(size) == 2
        else None,
        camera_matrix=_matrix(data["camera_matrix"], (3, 3), source, "camera_matrix"),
        dist_coeffs=_matrix(data.get("dist_coeffs", []), (-1,), source, "dist_coeffs"),
        distortion_model=_distortion_model((data.get("model") or {}).get("name")),
        sigma_fx_px=float(sigma_fx) if isinstance(sigma_fx, int | float) else None,
        sigma_refused_reason=stdev.get("refused_reason"),
        fit_outer_rms_px=held.get("fit_outer_ring_rms_px"),
        held_out_outer_rms_px=held.get("outer_ring_rms_px"),
        square_size_status=measurement.get("status"),
        square_size_m=measurement.get("square_size_m"),
        camera_consistency=data.get("camera_consistency"),
        camera_change=data.get("camera_change"),
        model_name=(data.get("model") or {}).get("name"),
        fit_rms_px=data.get("rms_px"),
        detector_rms_px=data.get("detector_rms_px"),
        fit_ring_rms_px=_inner_outer(held.get("by_radius") or []),
        image_circle=_recorded_circle(data.get("gates")),
        observed_region_px=_region(data.get("observed_region_px"), source),
        required_region_px=_region(data.get("required_region_px"), source, "required_region_px"),
        metric_gauge=data.get("metric_gauge") if isinstance(data.get("metric_gauge"), dict) else None,
        gauge_override=(data.get("provenance") or {}).get("gauge_override"),
        raw_numbers=[] if validated else _numbers(data),
    )


def _region(hull: Any, source: str, key: str = "observed_region_px") -> np.ndarray | None:
    """The artifact's observed (or required) region, (K, 2) px, or None when it records none."""
    return None if hull is None else _matrix(hull, (-1, 2), source, key)


def _recorded_circle(gates: Any) -> tuple[float, float, float] | None:
    """The image circle an artifact's coverage gate records (core.capture.image_circle), or None."""
    for gate in gates if isinstance(gates, list) else []:
        if isinstance(gate, dict) and gate.get("gate") == "coverage" and isinstance(gate.get("detail"), dict):
            circle = circle_from_detail(gate["detail"])
            return None if circle is None else circle.as_tuple()
    return None


def _inner_outer(rings: list[dict[str, Any]]) -> tuple[float | None, float | None]:
    fit = [r.get("fit_rms_px") for r in rings if isinstance(r, dict)]
    return (fit[0], fit[-1]) if len(fit) >= 2 else (None, None)


def _field_deg(facts: CalibrationFacts) -> float | None:
    """The lens's diagonal field (model_fit.diagonal_field_deg), None without an image size."""
    return (
        None
        if facts.image_size is None
        else model_fit.diagonal_field_deg(facts.camera_matrix, facts.image_size)
    )


def _misfit_rule(facts: CalibrationFacts) -> list[Finding]:
    if facts.fit_rms_px is None or facts.detector_rms_px is None or facts.model_name is None:
        return []  # only a calibctl solve records what the detector delivered
    return adopt(
        model_fit.check_model_misfit(
            facts.fit_rms_px,
            facts.detector_rms_px,
            facts.model_name,
            *facts.fit_ring_rms_px,
            field_deg=_field_deg(facts),
        )
    )


def _gauge_rule(facts: CalibrationFacts) -> list[Finding]:
    """``metric-gauge``: a failed distance gauge at capture (seed chapter 0) fails the calibration; an
    override with its reason (provenance.gauge_override) keeps it as a warning."""
    gauge = facts.metric_gauge or {}
    d = gauge.get("distance") or {}
    if not d or d.get("passed", True):
        return _board_gauge_rule(facts)
    lo, hi = d.get("ratio_limits") or (0.99, 1.01)
    message = (
        f"the metric gauge failed at capture: the fixture board is {d['recovered_m']:.4f} m away through the "
        f"{gauge.get('lens_model', '?')} lens, {d['ratio']:.3f}x the surveyed {d['reference_m']:.4f} m "
        "(needs "
        f"{lo}-{hi}): every metric output (translations, baselines, hand-eye) is scaled by it; the "
        "reprojection residual cannot show it (seed chapter 0)"
    )
    if facts.gauge_override:
        return [
            Finding(
                rule="metric-gauge",
                severity="warning",
                value=d["ratio"],
                message=f"{message}; overridden: {facts.gauge_override}",
            )
        ]
    return [
        Finding(
            rule="metric-gauge",
            severity="error",
            value=d["ratio"],
            message=message,
            fix="measure the board's squares (calipers) and register the measurement (`calibctl board add`), "
            "check the fixture's surveyed distance, then capture again; if the gauge, not the board, "
            "is wrong: solve with --override-gauge REASON (recorded in the calibration)",
        )
    ]


def _board_gauge_rule(facts: CalibrationFacts) -> list[Finding]:
    """``metric-gauge`` of the board revision: a gauge that failed with this board revision (another session,
    another camera, a check) fails every calibration made with it until the board is re-registered; an
    override with its reason keeps it as a warning."""
    if facts.board_gauge is None:
        return []
    board_ref, message = facts.board_gauge
    if facts.gauge_override:
        overridden = f"{message}; overridden: {facts.gauge_override}"
        return [Finding(rule="metric-gauge", severity="warning", message=overridden)]
    return [Finding(rule="metric-gauge", severity="error", message=message, fix=failure_fix(board_ref))]


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
    if facts.square_size_status == "measured-single":
        return [
            Finding(
                rule="square-size-single",
                severity="warning",
                message="the square size was measured once, with nothing independent to catch a wrong "
                "number (seed chapter 0: 23 mm typed for 25 mm leaves no residual)",
                fix="measure the pattern's span too: `calibctl board add NAME ... --span-mm ... "
                "--span-uncertainty-mm ... --span-instrument ...`",
            )
        ]
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
            fix="measure the squares (calipers), `calibctl board add NAME --square-mm ... --uncertainty-mm "
            "... "
            "--instrument ... --measured-by ... --measured-on ...`, and recalibrate",
        )
    ]


def adopt(check: lens_checks.Finding) -> list[Finding]:
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
                message="no held-out outer-ring error recorded: an over-fitted distortion model would pass "
                "unseen",
                fix="recalibrate with calibctl solve (k-fold held-out validation)",
                threshold=limits.outer_ring_ratio_max,
            )
        ]
    return adopt(
        lens_checks.check_outer_ring_holdout(
            facts.held_out_outer_rms_px,
            facts.fit_outer_rms_px,
            limits.outer_ring_ratio_max,
            model=facts.model_name,
        )
    )


def _one_camera_rule(facts: CalibrationFacts) -> list[Finding]:
    check = facts.camera_consistency
    if not check or not check.get("two_cameras_suspected"):
        return []
    a, b = check["group_a"], check["group_b"]
    held, cross = check["holdout_rms_px"], check["cross_rms_px"]

    def group(names: list[str], k: int) -> str:
        return (
            f"{len(names)} views ({named_list(names, 3)}; fx {check['fx_px'][k]:.1f}, cx "
            f"{check['cx_px'][k]:.1f}, "
            f"cy {check['cy_px'][k]:.1f} px alone)"
        )

    return [
        Finding(
            rule="one-camera",
            severity="error",
            value=check["ratio"],
            threshold=check["threshold"],
            message=f"the views disagree the way two cameras would: {group(a, 0)} and {group(b, 1)}; each "
            "group is "
            f"predicted {cross[0] / held[0]:.2f}x and {cross[1] / held[1]:.2f}x worse by the other's "
            "camera than by "
            f"its own (held-out {held[0]:.3f} / {held[1]:.3f} px); this calibration is a blend",
            fix="calibrate each camera from its own images (e.g. --source 'left*.jpg'); if it is one camera, "
            "check that nothing moved (focus, zoom, lens) during the capture",
        )
    ]


def _camera_change_rule(facts: CalibrationFacts) -> list[Finding]:
    """``camera-changed``: the views before and after a point in the capture disagree (a knocked or refocused
    lens); the calibration is a blend of two cameras, several sigma from both."""
    check = facts.camera_change
    if not check or not check.get("changed"):
        return []
    before, after = check["before_px"], check["after_px"]
    n_before, n_after = check["views"]
    return [
        Finding(
            rule="camera-changed",
            severity="error",
            value=check["chi2"],
            threshold=check["limit"],
            message=f"the camera changed during the session: the {n_before} views before "
            f"{check['first_view_after']} and the {n_after} from it on solve to fx {before['fx']:.1f} / "
            f"{after['fx']:.1f} px, cx {before['cx']:.1f} / {after['cx']:.1f}, cy {before['cy']:.1f} / "
            f"{after['cy']:.1f} px (chi2 {check['chi2']:.1f} over each side's own sigma, limit "
            f"{check['limit']:g}); this calibration is a blend of the two",
            fix=changed_hint(check["focal_step"], check["centre_step_px"]),
        )
    ]


def lint_facts(facts: CalibrationFacts, limits: LintThresholds, trace: str = "header") -> list[Finding]:
    """Every rule that applies to one calibration, in a stable order.

    ``trace`` says what vouches for the evidence only the solve knew (sigma(fx), held-out outer ring, square
    size): ``header`` (an artifact or a camera export's header: every rule runs), ``rig`` (a rig export's
    camera: its member was linted when the rig was solved, ``calibctl lint --rig`` lints it now) or ``none``
    (a ROS-rewritten camera_info, another tool's file). Without a header sigma(fx), the outer ring and the
    square size's provenance are not checked (the ``traceability`` warning names them and says to lint the
    stored version) instead of errors: a bare file carries none of them, and no new capture would add them."""
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
    findings = adopt(lens_checks.check_image_size(size, K))
    if size is not None and not findings:
        findings += adopt(lens_checks.check_principal_point(K, size, limits.principal_point_max_frac))
    if trace == "header":
        findings += adopt(
            lens_checks.check_sigma_fx(
                facts.sigma_fx_px,
                facts.sigma_refused_reason,
                limits.sigma_fx_max_px,
                facts.fit_rms_px,
                facts.detector_rms_px,
            )
        )
        findings += _outer_ring_rule(facts, limits)
        findings += _provenance_rule(facts)
    findings += _gauge_rule(facts)
    findings += _camera_change_rule(facts)
    findings += _one_camera_rule(facts)
    findings += _misfit_rule(facts)
    findings += adopt(lens_checks.check_aspect_ratio(K, limits.aspect_max_frac))
    if size is not None and facts.dist_coeffs.size:
        if facts.distortion_model == "equidistant":
            findings += adopt(
                lens_checks.check_equidistant_foldover(
                    K,
                    facts.dist_coeffs,
                    size,
                    facts.image_circle,
                    facts.observed_region_px,
                    facts.required_region_px,
                )
            )
        else:
            findings += adopt(
                lens_checks.check_distortion_foldover(
                    K,
                    facts.dist_coeffs,
                    size,
                    facts.image_circle,
                    model=facts.model_name,
                    observed_px=facts.observed_region_px,
                    required_px=facts.required_region_px,
                )
            )
    field = _field_deg(facts)
    return _misfit_first(findings, narrow=field is not None and field < model_fit.WIDE_FIELD_DEG)


# Rules whose fix assumes the lens model describes the lens: when model-misfit fails, their numbers are the
# misfit's symptoms (k1k2 on a fisheye also scatters sigma, the outer ring and the view groups) and their
# own fixes send the user the wrong way ("make the corners sharp", "two cameras").
_MISFIT_SYMPTOMS = ("sigma-fx", "outer-ring-holdout", "one-camera", "camera-changed", "distortion-foldover")


def _misfit_first(findings: list[Finding], narrow: bool = False) -> list[Finding]:
    """With model-misfit failed, the symptom rules' fixes point at its fix (the verdicts stay). On a
    ``narrow`` lens (below model_fit.WIDE_FIELD_DEG) with camera-changed or one-camera failed too, the misfit
    is the symptom: no lens model is wrong there, the intrinsics changed during the capture (a drifting ~60
    deg webcam), so model-misfit and its symptoms point at that rule's fix instead (camera-changed's
    first)."""
    misfit = next((f for f in findings if f.rule == "model-misfit"), None)
    if misfit is None:
        return findings
    drift = next((f for f in findings if f.rule == "camera-changed"), None) or next(
        (f for f in findings if f.rule == "one-camera"), None
    )
    if narrow and drift is not None:
        first = (
            f"first fix {drift.rule} ({drift.fix}), then judge this rule again: a lens this narrow misfits "
            "when its intrinsics change during the capture"
        )
        return [
            f.model_copy(update={"fix": first})
            if f.rule in ("model-misfit", *_MISFIT_SYMPTOMS) and f is not drift
            else f
            for f in findings
        ]
    first = (
        f"first fix model-misfit ({misfit.fix}), then judge this rule again: its numbers follow from "
        "the misfit"
    )
    return [f.model_copy(update={"fix": first}) if f.rule in _MISFIT_SYMPTOMS else f for f in findings]


def _status_rule(status: Any, ref: str) -> list[Finding]:
    if status != "rejected":
        return []
    return [
        Finding(
            rule="status",
            severity="error",
            message=f"{ref} is a rejected calibration (it failed its gates or lint when it was solved)",
            fix="export an accepted version (calibctl history SERIAL), or recalibrate",
        )
    ]


UNCHECKED_WITHOUT_EVIDENCE = "sigma(fx), the held-out outer ring and the square size's provenance"


def rig_trace_rules(header: trace_header.RigTraceHeader) -> list[Finding]:
    """Findings about a rig export's header: edited (content-hash), unhashed (traceability), rejected
    (status)."""
    if header.intact is None:
        return [
            Finding(
                rule="traceability",
                severity="warning",
                message=f"the header names rig {header.ref} but records no file-sha256: it cannot be checked",
                fix=f"export rig {header.ref} again",
            )
        ]
    if not header.intact:
        return [
            Finding(
                rule="content-hash",
                severity="error",
                message=f"file sha256 is {str(header.actual_file_sha256)[:12]} but its header records "
                f"{str(header.file_sha256)[:12]}: it was changed after `calibctl rig export` wrote rig "
                f"{header.ref}",
                fix=f"export rig {header.ref} again; never edit an export by hand",
            )
        ]
    if header.ref == trace_header.NOT_STORED:
        return [
            Finding(
                rule="traceability",
                severity="warning",
                message="written by `calibctl rig solve-folders` (solution sha256 "
                f"{header.rig_sha256[:12]}), "
                "not from a stored rig version: no store can vouch for its cameras' evidence",
                fix="for a robot, store the rig (`calibctl rig capture` + `rig solve`) and export it",
            )
        ] + _status_rule(header.status, "this rig solve")
    return _status_rule(header.status, f"rig {header.ref}")


def _trace_rules(loaded: formats.CalibrationFile) -> tuple[list[Finding], dict[str, Any]]:
    return trace_rules(loaded.header, loaded.rig_header)


def trace_rules(
    header: trace_header.TraceHeader | None, rig_header: trace_header.RigTraceHeader | None = None
) -> tuple[list[Finding], dict[str, Any]]:
    """Findings about an export's header (a camera's, else a rig's), and the evidence it vouches for (when
    intact; {} for a rig export or no header)."""
    if header is None and rig_header is not None:
        return rig_trace_rules(rig_header), {}
    if header is None:
        return [
            Finding(
                rule="traceability",
                severity="warning",
                message="no calibctl header: this file cannot be traced to a stored calibration; "
                f"linted on its numbers only ({UNCHECKED_WITHOUT_EVIDENCE} are not checked: the metric gauge "
                "of a bare file cannot be audited)",
                fix="lint what it was made from: the stored version (`calibctl lint --serial SERIAL`) or its "
                "export with the header (`calibctl export SERIAL --format ros|opencv`)",
            )
        ], {}
    if header.intact is None:
        return [
            Finding(
                rule="traceability",
                severity="warning",
                message=f"the header names {header.ref} but records no file-sha256 (an older calibctl "
                "wrote it): "
                "its numbers cannot be checked against that calibration",
                fix=f"export {header.ref} again, or lint it with --db URL: its numbers are then compared "
                "with the stored version",
            )
        ], {}
    if not header.intact:
        return [
            Finding(
                rule="content-hash",
                severity="error",
                message=f"file sha256 is {str(header.actual_file_sha256)[:12]} but its header records "
                f"{str(header.file_sha256)[:12]}: it was changed after `calibctl export` wrote {header.ref}",
                fix=f"export {header.ref} again; never edit an export by hand",
            )
        ], {}
    return _status_rule(header.status, header.ref), header.evidence


def lint_file(loaded: formats.CalibrationFile, limits: LintThresholds) -> LintResult:
    """Every rule for one calibration file (or stored artifact), whatever its format."""
    data, source = loaded.data, loaded.source
    if loaded.kind == "calibctl":
        findings = _document_rules(data, source)
        findings += _status_rule(data.get("status"), f"{data.get('serial')}@{data.get('version')}")
        return LintResult(
            source, loaded.kind, findings + lint_facts(facts_from_document(data, source), limits)
        )
    findings, evidence = _trace_rules(loaded)
    if loaded.kind == "ros":
        structure = ros_camera_info.check_camera_info(data)
        findings += structure
        if has_errors(structure):  # ROS would not load it: its numbers describe no camera
            return LintResult(source, loaded.kind, findings)
        facts = _ros_facts(data, source)
    else:
        facts = _opencv_facts(data, source)
    return LintResult(
        source,
        loaded.kind,
        findings
        + lint_facts(
            with_evidence(facts, evidence), limits, trace_of(evidence, loaded.header, loaded.rig_header)
        ),
    )


def trace_of(evidence: dict[str, Any], header: object, rig_header: object) -> str:
    """``lint_facts``' trace: a camera header's evidence, a rig export, or nothing."""
    return "header" if evidence else "rig" if header is None and rig_header is not None else "none"


def lint_artifact(
    art: CalibrationArtifact, limits: LintThresholds, gauge_failures: Sequence[GaugeFailure] = ()
) -> LintResult:
    """Every rule for a stored calibration (rig members use it too); ``gauge_failures``: the store's failed
    gauges of its board revision (``Store.failed_gauges``)."""
    return _lint_stored(art, limits, None, gauge_failures)


def lint_files(paths: list[Path], limits: LintThresholds) -> list[LintResult]:
    return [lint_file(formats.load_calibration(p), limits) for p in paths]


def _no_active_version(serial: str, statuses: dict[int, str]) -> LintResult:
    """A serial with nothing active is a finding: the camera has no calibration a robot may load."""
    accepted = [v for v, st in statuses.items() if st == "accepted"]
    listing = ", ".join(f"{v} ({st})" for v, st in statuses.items())
    if accepted:
        message, fix = (
            f"{serial} has no active version (versions: {listing})",
            f"activate an accepted one: calibctl rollback {serial} --to {accepted[-1]} --reason '...'",
        )
    else:
        message, fix = (
            f"{serial} has no accepted calibration (versions: {listing})",
            f"recalibrate it: calibctl calibrate --serial {serial} --board BOARD --source ...",
        )
    finding = Finding(rule="no-active-version", severity="error", message=message, fix=fix)
    return LintResult(source=serial, kind="calibctl", findings=[finding])


def board_gauge_fact(
    board_ref: str, session_id: str | None, failures: Sequence[GaugeFailure]
) -> tuple[str, str] | None:
    """``CalibrationFacts.board_gauge`` from the store's failed gauges of the board revision, leaving out the
    calibration's own session (its own gauge is ``metric_gauge``)."""
    others = [f for f in failures if f.record != f"session {session_id}"]
    return (board_ref, failure_text(board_ref, others)) if others else None


def _lint_stored(
    art: CalibrationArtifact,
    limits: LintThresholds,
    trusted: TrustedKeys | None,
    gauge_failures: Sequence[GaugeFailure] = (),
) -> LintResult:
    """Every rule for a stored version. Its schema and integrity were checked when the store read it, so the
    document rules (schema, content-hash) are not run again. ``gauge_failures``: the store's failed gauges of
    its board revision."""
    data = art.model_dump(
        mode="json", include=FACT_FIELDS
    )  # the fact fields only: a third of the dump's cost
    facts = facts_from_document(data, art.ref, validated=True)
    facts.board_gauge = board_gauge_fact(art.board.ref, art.provenance.session_id, gauge_failures)
    findings = _status_rule(art.status, art.ref) + lint_facts(facts, limits)
    result = LintResult(art.ref, "calibctl", findings)
    if trusted is not None:
        signature_rule(result, art, trusted)
    return result


def unverified_result(source: str, kind: str, refused: UnverifiedRecord) -> LintResult:
    """Lint's verdict on a stored record that does not verify: a ``content-hash`` error (exit 1), where a
    read that would use the record cannot run (exit 2)."""
    finding = Finding(rule="content-hash", severity="error", message=refused.message, fix=refused.hint)
    return LintResult(source=source, kind=kind, findings=[finding])


def lint_store(
    settings: Settings, serial: str | None, all_serials: bool, trusted: TrustedKeys | None = None
) -> list[LintResult]:
    """Lint the active version of one serial, or of every serial in the store (an empty store is an error:
    a CI job pointed at the wrong --db must not pass with nothing checked).

    ``--all`` reads in bulk: every active version in one query, each checked by its record's chain hash
    (sha256 over its stored bytes and columns; a mismatch is a ``content-hash`` error for that serial, the
    others are still linted); ``--serial`` re-derives the content hash as every single read does."""
    from calibctl.workflows.store_admin.records import open_store

    with open_store(settings) as store:
        if all_serials:
            active, inactive = store.active_artifacts()
        else:
            name = serial or ""
            found: CalibrationArtifact | UnverifiedRecord | None = None
            versions: dict[int, str] = {}
            try:
                versions = {a.version: a.status for a in store.list_artifacts(name)}
                if store.active_version(name) is not None:
                    found = store.get_artifact(name, None)
            except UnverifiedRecord as exc:  # a verdict here, as with --all (a read of it exits 2)
                found = exc
            active, inactive = ({name: found}, {}) if found else ({}, {name: versions})
        if not active and not inactive:
            raise NotFoundError(
                f"nothing to lint: the store {store.url} holds no calibrations",
                "check --db / CALIBCTL_DB, or calibrate a camera first",
            )
        gauges = store.failed_gauges(
            a.board.ref for a in active.values() if isinstance(a, CalibrationArtifact)
        )
    results = []
    for name in sorted([*active, *inactive]):
        found_or_error = active.get(name)
        if found_or_error is None:
            results.append(_no_active_version(name, inactive[name]))
        elif isinstance(found_or_error, UnverifiedRecord):
            results.append(unverified_result(name, "calibctl", found_or_error))
        else:
            found = found_or_error
            results.append(_lint_stored(found, settings.lint, trusted, gauges.get(found.board.ref, ())))
    return results


def signature_rule(
    result: LintResult, art: CalibrationArtifact | dict[str, Any], trusted: TrustedKeys
) -> None:
    """Add a ``signature`` error unless ``art`` is an artifact signed by a trusted key."""
    if isinstance(art, dict):
        try:
            art = CalibrationArtifact.model_validate(art)
        except ValidationError:
            problem: str | None = "cannot be checked: it is not a valid artifact"
        else:
            problem = keys.signature_problem(art, trusted)
    else:
        problem = keys.signature_problem(art, trusted)
    if problem is not None:
        fix = (
            "lint the artifact as the signing store exported it, and trust that store's public key "
            "(--trusted-keys DIR)"
        )
        result.findings.append(
            Finding(rule="signature", severity="error", message=f"{result.source} {problem}", fix=fix)
        )
