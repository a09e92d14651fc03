"""Rig lint and the rig records: history, show, rollback (export: workflows.rig.rig_export).

Rules (errors fail lint, exit 1):
- ``rig-stale-member``: a member's active calibration is not the serial@version + content_sha256 the
  rig solve used (re-calibrated or rolled back since): the rig must be re-solved.
- ``baseline-design``: a pair's solved baseline is outside the registered design value +- tolerance.
- ``epipolar``: a pair's held-out epipolar RMS is above ``epipolar_max_px_at_720`` x rows / 720
  (0.5 px at 720 rows by default, per station; DepthAI's factory flow gates at 0.5-0.6 px). Its fix
  names the lens model when a member of the pair fails ``model-misfit``.
- ``loop-closure``: a cycle's residual has Mahalanobis distance above ``loop_closure_max_mahalanobis``
  (4.48 = sqrt of chi-square(6) at 99.7 %).
- the camera rules for every member's active calibration (``member:<rule>``).
``baseline-design``, ``epipolar`` and ``loop-closure`` read only the solve's numbers
(``solved_rig_findings``): ``rig solve-folders`` applies them too, with each self-calibrated member's
``model-misfit`` (workflows.rig.rig_folders).
- hand-eye edges (workflows.edges, its hand-eye kind): ``handeye-gates`` (a gate of the stored result failed),
  ``handeye-stale-member`` (the camera whose calibration gave the board poses was re-calibrated since),
  ``handeye-uncertainty`` (an accepted edge without a one-sigma);
- camera-LiDAR edges (the same table, its LiDAR kind): ``lidar-gates``,
  ``lidar-stale-member`` (the camera whose calibration posed the board was re-calibrated since the edge was
  solved), ``lidar-uncertainty`` (no positive-definite covariance: error; a one-sigma over 10 mm or 0.5 deg:
  warning);
- camera-IMU edges (the same table, its IMU kind): ``imu-gates``, ``imu-stale-member`` (the camera whose
  intrinsics were held was re-calibrated since), ``imu-uncertainty`` (as LiDAR's), ``imu-dropped``.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from typing import TYPE_CHECKING

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.lint import Finding
from calibctl.artifacts.rig import (
    DesignBaseline,
    RigActivation,
    RigCalibration,
    RigDefinition,
    RigLoop,
    RigPair,
)
from calibctl.config import LintThresholds, Settings
from calibctl.errors import NotFoundError, UnverifiedRecord, UsageError
from calibctl.signing import TrustedKeys
from calibctl.workflows.edges.kinds import evidence_of
from calibctl.workflows.edges.versions import cal_versions, edge_findings
from calibctl.workflows.lint.lint import LintResult, lint_artifact, unverified_result
from calibctl.workflows.store_admin import keys
from calibctl.workflows.store_admin.records import check_rollback_request, open_store

if TYPE_CHECKING:
    from calibctl.store.gauge_failures import GaugeFailure

_DESIGN = re.compile(r"^(?P<a>[^:=]+):(?P<b>[^:=]+)=(?P<mm>[0-9.]+)(?:(?:\+-|\+/-|±)(?P<tol>[0-9.]+))?$")
DEFAULT_DESIGN_TOL_MM = 0.5


def parse_design(text: str) -> DesignBaseline:
    """``A:B=75.0+-0.5`` (mm; tolerance defaults to 0.5 mm)."""
    m = _DESIGN.match(text.strip())
    if not m:
        raise UsageError(f"--design-baseline-mm must look like A:B=75.0+-0.5, got {text!r}")
    tol = float(m.group("tol")) if m.group("tol") else DEFAULT_DESIGN_TOL_MM
    return DesignBaseline(a=m.group("a"), b=m.group("b"), baseline_mm=float(m.group("mm")), tolerance_mm=tol)


def parse_rig_ref(ref: str) -> tuple[str, int | None]:
    name, sep, version = ref.strip().partition("@")
    if not name or (sep and not version.isdigit()):
        raise UsageError(f"'{ref}' is not RIG or RIG@N")
    return name, int(version) if sep else None


def solved_rig_findings(
    pairs: Sequence[RigPair],
    loops: Sequence[RigLoop],
    rows: Mapping[str, int],
    designs: Sequence[DesignBaseline],
    limits: LintThresholds,
    misfit: Collection[str] = (),
) -> list[Finding]:
    """The rules that read only the solve's own numbers, no store: ``baseline-design``, ``epipolar``,
    ``loop-closure`` (``rig solve`` and ``rig lint`` on a stored version, ``rig solve-folders`` on its run).

    Args:
        rows: image height (px) per camera, which scales the epipolar limit.
        misfit: cameras whose own lens model fails ``model-misfit``; an epipolar error of their pair then
            names the lens model as its likely cause instead of the capture.
    """
    findings: list[Finding] = []
    by_pair = {frozenset((p.a, p.b)): p for p in pairs}
    for d in designs:
        p = by_pair.get(frozenset((d.a, d.b)))
        if p is not None and abs(p.baseline_mm - d.baseline_mm) > d.tolerance_mm:
            findings.append(
                Finding(
                    rule="baseline-design",
                    severity="error",
                    value=p.baseline_mm,
                    threshold=d.tolerance_mm,
                    message=f"{d.a}-{d.b}: baseline {p.baseline_mm:.3f} +/- {p.sigma_baseline_mm:.3f} mm, "
                    "design "
                    f"{d.baseline_mm:.3f} +/- {d.tolerance_mm:.3f} mm",
                    fix="check the mount (a camera moved or the wrong rig was captured) and the board's "
                    "square size",
                )
            )
    for p in pairs:
        limit = limits.epipolar_max_px_at_720 * rows[p.a] / 720.0
        if p.epipolar_rms_px is not None and p.epipolar_rms_px > limit:
            lens = [c for c in (p.a, p.b) if c in misfit]
            fix = (
                f"the lens model of {' and '.join(lens)} does not describe the lens (member:model-misfit), "
                "the likely cause: calibrate with the model that rule names (a circular fisheye: --model "
                "fisheye), then re-solve"
                if lens
                else "re-capture with a still board seen by both cameras, then re-solve (a board that moves "
                "between the cameras' exposures shifts each camera's view as a whole: software-synced "
                "cameras' timestamps do not record it)"
            )
            findings.append(
                Finding(
                    rule="epipolar",
                    severity="error",
                    value=p.epipolar_rms_px,
                    threshold=limit,
                    message=f"{p.a}-{p.b}: held-out epipolar RMS {p.epipolar_rms_px:.3f} px > {limit:.3f} px",
                    fix=fix,
                )
            )
    for lc in loops:
        if lc.mahalanobis > limits.loop_closure_max_mahalanobis:
            findings.append(
                Finding(
                    rule="loop-closure",
                    severity="error",
                    value=lc.mahalanobis,
                    threshold=limits.loop_closure_max_mahalanobis,
                    message=f"{'-'.join(lc.cycle)}: loop residual {lc.rotation_deg:.4f} deg / "
                    f"{lc.translation_mm:.3f} mm "
                    f"is {lc.mahalanobis:.2f} sigma (Mahalanobis)",
                    fix="a pair disagrees with the rest of the rig: check its shared views and that no "
                    "camera moved",
                )
            )
    return findings


def member_finding(camera: str, finding: Finding) -> Finding:
    """A member camera's own finding as a rig finding (``member:<rule>``, the message names the camera)."""
    return finding.model_copy(
        update={"rule": f"member:{finding.rule}", "message": f"{camera}: {finding.message}"}
    )


def rig_findings(
    cal: RigCalibration,
    rig: RigDefinition,
    active: Mapping[str, CalibrationArtifact | None],
    limits: LintThresholds,
    gauge_failures: Mapping[str, Sequence[GaugeFailure]] | None = None,
) -> list[Finding]:
    """Every rig rule on ``cal`` given the members' currently active calibrations; ``gauge_failures``: the
    store's failed gauges by board revision (a member made with a failed board is ``member:metric-gauge``)."""
    gauges = gauge_failures or {}
    findings: list[Finding] = []
    for m in cal.members:
        now = active.get(m.serial)
        if now is None or (now.version, now.content_sha256) != (m.version, m.content_sha256):
            current = f"{now.serial}@{now.version}" if now is not None else "no active calibration"
            findings.append(
                Finding(
                    rule="rig-stale-member",
                    severity="error",
                    message=f"{m.serial}: the rig was solved with {m.serial}@{m.version}, the active one "
                    f"is now {current}",
                    fix=f"re-solve the rig (`calibctl rig solve {cal.rig}`)",
                )
            )
    members = [
        (art, lint_artifact(art, limits, gauges.get(art.board.ref, ())).findings)
        for art in active.values()
        if art is not None
    ]
    misfit = {art.serial for art, found in members if any(f.rule == "model-misfit" for f in found)}
    findings += solved_rig_findings(
        cal.pairs,
        cal.loops,
        {m.serial: m.image_size[1] for m in cal.members},
        rig.design_baselines,
        limits,
        misfit,
    )
    findings += [member_finding(art.ref, f) for art, found in members for f in found]
    return findings


def _active_members(store: object, cal: RigCalibration) -> dict[str, CalibrationArtifact | None]:
    out: dict[str, CalibrationArtifact | None] = {}
    for m in cal.members:
        try:
            out[m.serial] = store.get_artifact(m.serial, None)  # type: ignore[attr-defined]
        except NotFoundError:
            out[m.serial] = None
    return out


def lint_rig(settings: Settings, ref: str, trusted: TrustedKeys | None = None) -> LintResult:
    """Lint a stored rig calibration (the active version unless RIG@N) against the store as it is now.
    ``trusted`` (``lint --require-signature``): every member version the rig used must be signed by a
    trusted key, and so must the rig version itself."""
    name, version = parse_rig_ref(ref)
    with open_store(settings) as store:
        try:
            rig = store.get_rig(name)
            cal = store.get_rig_calibration(name, version)
            members = _active_members(store, cal)
            gauges = store.failed_gauges(a.board.ref for a in members.values() if a is not None)
            findings = rig_findings(cal, rig, members, settings.lint, gauges)
            findings += edge_findings(evidence_of(cal), cal_versions(store, cal))
            if trusted is not None:
                findings += _signature_findings(store, cal, trusted)
        except UnverifiedRecord as exc:  # the rig, its definition or a member: the verdict on it is lint's
            return unverified_result(f"rig {ref}", "rig", exc)
    return LintResult(source=f"rig {cal.rig}@{cal.version}", kind="rig", findings=findings)


def _signature_findings(store: object, cal: RigCalibration, trusted: TrustedKeys) -> list[Finding]:
    fix = "a robot must load only signed calibrations: sign the store (`calibctl keys init`) and re-solve"
    own = keys.signature_problem(cal, trusted)
    findings = (
        []
        if own is None
        else [Finding(rule="signature", severity="error", fix=fix, message=f"rig {cal.ref} {own}")]
    )
    for m in cal.members:
        try:
            art = store.get_artifact(m.serial, m.version)  # type: ignore[attr-defined]
        except NotFoundError:
            problem: str | None = "is not in this store"
        else:
            problem = keys.signature_problem(art, trusted)
        if problem is not None:
            findings.append(
                Finding(
                    rule="signature",
                    severity="error",
                    fix=fix,
                    message=f"member {m.serial}@{m.version} {problem}",
                )
            )
    return findings


def history(settings: Settings, rig: str) -> tuple[list[RigCalibration], int | None, list[RigActivation]]:
    with open_store(settings) as store:
        store.get_rig(rig)
        return store.list_rig_calibrations(rig), store.active_rig_version(rig), store.rig_events(rig)


def show(settings: Settings, ref: str) -> RigCalibration:
    name, version = parse_rig_ref(ref)
    with open_store(settings) as store:
        return store.get_rig_calibration(name, version)


def rollback(
    settings: Settings, rig: str, to_version: int, reason: str, expected_active: int | None = None
) -> RigActivation | None:
    """Roll the rig back as a compare-and-set, like a camera's (``records.rollback``): against
    ``expected_active`` (what the technician saw) when given, else against the active version read first;
    a solve, hand-eye edge or rollback stored in between refuses it (exit 2) instead of being undone.
    None when ``to_version`` is the active version already (nothing written)."""
    check_rollback_request(to_version, reason)
    with open_store(settings, write=True) as store:
        seen = store.active_rig_version(rig) if expected_active is None else expected_active
        return store.rollback_rig(
            rig,
            to_version,
            reason=reason,
            actor=settings.operator,
            station=settings.station,
            expected_active=seen,
        )
