"""calibctl solve: stored corners -> an immutable, linted calibration artifact (the serial's next version).

The numbers come from calibctl.core (cv2.calibrateCameraExtended with our own covariance, k-fold
held-out validation, outlier flags, the --model auto rule); this module turns them into the artifact,
runs lint on it, and writes it: ``accepted`` and active when lint passes (unless --no-activate),
``rejected`` and never active otherwise.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

from calibctl import __version__
from calibctl.artifacts.calibration import (
    UNSEALED,
    CalibrationArtifact,
    CameraChange,
    CameraConsistency,
    DistortionModelInfo,
    HeldOut,
    ParameterCovariance,
    Provenance,
    RejectedCorner,
    RingRms,
    Uncertainty,
    ViewLevelSigma,
    ViewResult,
)
from calibctl.artifacts.common import utc_now
from calibctl.artifacts.lint import has_errors
from calibctl.artifacts.session import CaptureSession
from calibctl.config import Settings
from calibctl.core.capture.camera_split import CameraSplit, check_one_camera, spread_views
from calibctl.core.capture.projection_gate import Region, parse_region
from calibctl.core.intrinsics import solve as core_solve
from calibctl.core.intrinsics.camera_change import STEP_PARAMETERS, ChangeVerdict, judge_change
from calibctl.core.intrinsics.covariance import VIEW_FACTOR_RULE
from calibctl.core.intrinsics.lens_checks import observed_region_px
from calibctl.core.intrinsics.model_fit import noise_floor_px
from calibctl.core.intrinsics.model_select import select_model
from calibctl.core.intrinsics.outliers import (
    CornerRejection,
    OutlierReport,
    flag_outliers,
    solve_dropping_outliers,
    solve_rejecting_corners,
)
from calibctl.core.intrinsics.recent_answers import RecentAnswers, values_digest
from calibctl.core.intrinsics.solve import IntrinsicsSolution, get_model
from calibctl.core.intrinsics.validation import (
    HoldoutReport,
    ResidualBreakdown,
    agree_with_folds,
    validate_holdout,
)
from calibctl.core.lanes import Lanes
from calibctl.errors import UsageError
from calibctl.workflows.board.boards import board_spec
from calibctl.workflows.board.gauge_failures import board_failures
from calibctl.workflows.camera.image_circles import checked_image_circle, with_circle
from calibctl.workflows.camera.verdict_lanes import verdict_lanes
from calibctl.workflows.lint.lint import board_gauge_fact, facts_from_document, lint_facts
from calibctl.workflows.store_admin.records import open_store

MODEL_CHOICES = ("k1k2", "k1k2k3", "k1k2p1p2k3", "rational", "opencv-default", "fisheye", "auto")
_OCTANT_LABELS = tuple(f"octant {i}" for i in range(8))
_FLAG_NAMES = (
    "CALIB_USE_INTRINSIC_GUESS",
    "CALIB_FIX_ASPECT_RATIO",
    "CALIB_FIX_PRINCIPAL_POINT",
    "CALIB_ZERO_TANGENT_DIST",
    "CALIB_FIX_K1",
    "CALIB_FIX_K2",
    "CALIB_FIX_K3",
    "CALIB_FIX_K4",
    "CALIB_FIX_K5",
    "CALIB_FIX_K6",
    "CALIB_RATIONAL_MODEL",
    "CALIB_RECOMPUTE_EXTRINSIC",
    "CALIB_FIX_SKEW",
)


@dataclass(frozen=True)
class SolveRequest:
    session_id: str | None = None
    serial: str | None = None
    model: str = core_solve.DEFAULT_MODEL
    activate: bool = True
    drop_outliers: bool = False
    report_dir: Path | None = None  # write SERIAL-vN-report.html here for the new version (accepted or not)
    image_circle: tuple[float, float, float] | None = None  # --image-circle CX,CY,R px, recorded for lint
    # --override-gauge REASON: solve a session whose metric gauge failed into an artifact lint can accept; the
    # reason is recorded in the provenance and lint keeps the failed gauge as a warning
    override_gauge: str | None = None


@dataclass(frozen=True)
class SolveOutcome:
    artifact: CalibrationArtifact
    active: bool
    outlier_corners: list[dict[str, float | int | str]]
    report_path: Path | None = None


def flag_names(flags: int) -> list[str]:
    return [
        name for name in _FLAG_NAMES if flags & int(getattr(cv2, name, None) or getattr(core_solve, name))
    ]


def _rings(
    fit: ResidualBreakdown, held: ResidualBreakdown, labels: Sequence[str], which: str
) -> list[RingRms]:
    fit_rms = fit.ring_rms_px if which == "ring" else fit.octant_rms_px
    held_rms = held.ring_rms_px if which == "ring" else held.octant_rms_px
    counts = fit.ring_counts if which == "ring" else fit.octant_counts
    return [
        RingRms(
            label=label,
            fit_rms_px=float(f) if np.isfinite(f) else None,
            held_out_rms_px=float(h) if np.isfinite(h) else None,
            count=int(c),
        )
        for label, f, h, c in zip(labels, fit_rms, held_rms, counts, strict=True)
    ]


def _held_out(report: HoldoutReport) -> HeldOut:
    edges = report.fit.radius_edges_px
    bounds = [0.0, *[float(e) for e in edges], None]
    ring_labels = [
        f"quintile {i + 1} (r {bounds[i]:.0f}-{bounds[i + 1]:.0f} px)"
        if bounds[i + 1] is not None
        else f"quintile {i + 1} (r >= {bounds[i]:.0f} px)"
        for i in range(5)
    ]
    finite = lambda v: float(v) if np.isfinite(v) else None  # noqa: E731
    return HeldOut(
        k_folds=report.n_folds,
        rms_px=finite(report.holdout_rms_px),
        outer_ring_rms_px=finite(report.holdout_outer_rms_px),
        fit_outer_ring_rms_px=finite(report.fit_outer_rms_px),
        by_radius=_rings(report.fit, report.holdout, ring_labels, "ring"),
        by_octant=_rings(report.fit, report.holdout, _OCTANT_LABELS, "octant"),
    )


class SolveNumbers(NamedTuple):
    """What ``_solve_numbers`` computes of one session: everything the artifact records."""

    model_name: str
    solution: IntrinsicsSolution
    first: IntrinsicsSolution  # every view's pose and RMS, the views --drop-outliers removes included
    outliers: OutlierReport
    kept: list[int]
    dropped: tuple[int, ...]
    holdout: HoldoutReport
    trail: list[dict[str, float | str | bool]]
    rejection: CornerRejection
    consistency: CameraConsistency | None
    detector_rms: float | None
    change: CameraChange | None


def _solve_numbers(session: CaptureSession, request: SolveRequest, lanes: Lanes) -> SolveNumbers:
    """Run the core solve pipeline on a session's corners. Returns everything the artifact records.

    The one-camera split test needs only the kept corners (of at most CAPTURE_MAX_VIEWS views, spread evenly,
    as at capture) and the model, so it runs on another lane (verdict_lanes) beside the held-out folds and the
    model-misfit floor; the folds and the floor's lens models spread over the lanes too. The numbers are those
    of the sequential order."""
    size = session.image_size
    if size is None or not session.views:
        raise UsageError(f"session {session.session_id} has no accepted views to solve")
    model_points = board_spec(session.board).object_points()
    ids = [np.asarray(v.corner_ids, dtype=np.int64) for v in session.views]
    obj = [model_points[i] for i in ids]
    img = [np.asarray(v.corners_px, dtype=np.float64) for v in session.views]
    trail: list[dict[str, float | str | bool]] = []
    if request.model == "auto":
        # the model is chosen on every corner; the corner rule then runs under the chosen model
        selection = select_model(obj, img, size, lanes=lanes)
        model_name = selection.chosen
        trail = [{k: v for k, v in c.__dict__.items() if v is not None} for c in selection.trail]
    else:
        model_name = get_model(request.model).name
    rejection = solve_rejecting_corners(obj, img, size, model_name, ids)
    obj, img, solution = rejection.kept(obj), rejection.kept(img), rejection.solution
    outliers = flag_outliers(solution, rejection.kept(ids))
    first = solution  # every view's pose and RMS, including views --drop-outliers removes below
    kept = list(range(len(obj)))
    dropped: tuple[int, ...] = ()
    if request.drop_outliers and outliers.outlier_views:
        result = solve_dropping_outliers(obj, img, size, model_name)
        solution, dropped, kept = result.solution, result.dropped_views, list(result.kept_views)
    kept_obj, kept_img = [obj[i] for i in kept], [img[i] for i in kept]
    # the capture gate's views (spread_views): with the gate's corners and model, the gate's answer
    checked = [kept[i] for i in spread_views(len(kept))]
    split = lanes.start(
        lambda: check_one_camera(
            [obj[i] for i in checked], [img[i] for i in checked], size, model_name, lanes=lanes
        )
    )
    changed = lanes.start(partial(judge_change, solution, kept_obj, kept_img, size))  # this solve's fit
    try:
        holdout = validate_holdout(kept_obj, kept_img, size, model_name, fit=solution, lanes=lanes)
        # the fit RMS and the held-out RMS the artifact records must come from one minimum
        solution, holdout = agree_with_folds(kept_obj, kept_img, size, solution, holdout, lanes=lanes)
        # the model-misfit rule's floor: lens-free 4x4 patches or the best lens model's own residuals, the
        # smaller (the lens models are solved only when the fit could be a misfit: core.intrinsics.model_fit);
        # on every corner the rule kept, the views --drop-outliers removes included
        detector_rms = noise_floor_px(obj, img, size, float(solution.rms_px), lanes=lanes)
    except BaseException:
        split.settle()
        changed.settle()
        raise
    found = split.result()
    consistency = None if found is None else _consistency(found, [session.views[i].name for i in checked])
    change = _change(changed.result(), [session.views[i].name for i in kept])
    return SolveNumbers(
        model_name,
        solution,
        first,
        outliers,
        kept,
        dropped,
        holdout,
        trail,
        rejection,
        consistency,
        detector_rms,
        change,
    )


# The numbers of sessions started before they were written (start_numbers), by a digest of what
# _solve_numbers reads; each is taken once, by the solve of the same values.
_EARLY: RecentAnswers[Future[SolveNumbers]] = RecentAnswers(2)


def _numbers_key(session: CaptureSession, request: SolveRequest) -> bytes:
    """A digest of everything ``_solve_numbers`` reads: the views (names, corner ids, corners), the image
    size, the board, the model and the outlier rule."""
    return values_digest(
        [np.asarray(v.corner_ids, np.float64) for v in session.views],
        [np.asarray(v.corners_px, np.float64) for v in session.views],
        session.session_id,
        tuple(session.image_size or ()),
        repr(board_spec(session.board)),
        request.model,
        request.drop_outliers,
        tuple(v.name for v in session.views),
    )


def start_numbers(session: CaptureSession, request: SolveRequest, jobs: int, executor: Executor) -> None:
    """Start the solve's numbers of an accepted session on ``executor`` (on ``jobs`` verdict lanes) while the
    session is written and read back: ``build_artifact`` of the same values takes them instead of computing
    them again. The same function of the same values: the numbers are those of the plain order."""
    if session.status != "accepted" or not session.views or session.image_size is None:
        return

    def numbers() -> SolveNumbers:
        with verdict_lanes(jobs) as lanes:
            return _solve_numbers(session, request, lanes)

    _EARLY.answer(_numbers_key(session, request), lambda: executor.submit(numbers))


def _change(verdict: ChangeVerdict | None, names: list[str]) -> CameraChange | None:
    if verdict is None:
        return None
    return CameraChange(
        first_view_after=names[verdict.split],
        views=(verdict.split, len(names) - verdict.split),
        before_px=dict(zip(STEP_PARAMETERS, verdict.before.tolist(), strict=True)),
        after_px=dict(zip(STEP_PARAMETERS, verdict.after.tolist(), strict=True)),
        focal_step=verdict.focal_step,
        centre_step_px=verdict.centre_step_px,
        chi2=verdict.chi2,
        limit=verdict.limit,
        changed=verdict.changed,
    )


def _consistency(split: CameraSplit, names: list[str]) -> CameraConsistency:
    Ka, Kb = split.camera_a, split.camera_b
    return CameraConsistency(
        group_a=[names[i] for i in split.group_a],
        group_b=[names[i] for i in split.group_b],
        holdout_rms_px=split.holdout_rms_px,
        cross_rms_px=split.cross_rms_px,
        fx_px=(float(Ka[0, 0]), float(Kb[0, 0])),
        cx_px=(float(Ka[0, 2]), float(Kb[0, 2])),
        cy_px=(float(Ka[1, 2]), float(Kb[1, 2])),
        ratio=split.ratio,
        threshold=split.threshold,
        two_cameras_suspected=split.suspected,
    )


def _views(
    session: CaptureSession, solution: IntrinsicsSolution, first: IntrinsicsSolution, outliers, kept, dropped
) -> list[ViewResult]:
    """Per-view RMS and pose from the final solve; a dropped view keeps those of the solve that flagged it."""
    out, pos = [], {v: i for i, v in enumerate(kept)}
    outlier_views = set(outliers.outlier_views)
    for i, view in enumerate(session.views):
        src, j = (solution, pos[i]) if i in pos else (first, i)
        res = src.residuals_px[j]
        out.append(
            ViewResult(
                name=view.name,
                rms_px=float(src.per_view_rms_px[j]),
                rvec=(float(src.rvecs[j][0]), float(src.rvecs[j][1]), float(src.rvecs[j][2])),
                tvec_m=(float(src.tvecs[j][0]), float(src.tvecs[j][1]), float(src.tvecs[j][2])),
                outlier=i in outlier_views,
                dropped=i in dropped,
                worst_corner_px=float(np.linalg.norm(res, axis=1).max()) if len(res) else None,
            )
        )
    return out


def _observed_region(corners_px: list[np.ndarray]) -> list[tuple[float, float]] | None:
    hull = observed_region_px(corners_px)
    return None if hull is None else [(float(u), float(v)) for u, v in hull]


def _covariance(sol: IntrinsicsSolution) -> ParameterCovariance | None:
    """The matrix behind sigma, stored so a report can propagate it (absent whenever sigma was refused)."""
    cov = sol.covariance
    if cov is None or cov.covariance is None or sol.sigma_refused_reason:
        return None
    return ParameterCovariance(
        parameters=list(cov.names),
        matrix=[[float(x) for x in row] for row in cov.covariance],
        aspect_ratio=None if sol.aspect_ratio is None else float(sol.aspect_ratio),
    )


def _view_level(sol: IntrinsicsSolution) -> ViewLevelSigma | None:
    """Which covariance sigma is and the factor that decided it (absent when no factor was computed)."""
    cov = sol.covariance
    if cov is None or cov.covariance is None or cov.view_factor is None or sol.sigma_refused_reason:
        return None
    return ViewLevelSigma(
        sigma_factor=float(cov.view_factor),
        views=int(cov.n_views),
        used="view-level" if cov.inflated else "jacobian",
        rule=VIEW_FACTOR_RULE,
    )


def _gates(session: CaptureSession, request: SolveRequest) -> list:
    """The session's gates; a --image-circle given to the solve is recorded in the coverage gate."""
    if request.image_circle is None or session.image_size is None:
        return list(session.gates)
    return with_circle(list(session.gates), checked_image_circle(request.image_circle, session.image_size))


def station_region(
    settings: Settings, image_size: tuple[int, int], circle_px: tuple[float, float, float] | None
) -> Region:
    """The station's gates.projection_region parsed (UsageError, exit 2, naming it when it is not a region of
    this image)."""
    try:
        return parse_region(settings.gates.projection_region, image_size, circle_px)
    except ValueError as exc:
        raise UsageError(
            f"station setting gates.projection_region: {exc}",
            "declare auto, image, circle or a box U0,V0,U1,V1 inside the image, in pixels",
        ) from exc


def _with_required_region(art: CalibrationArtifact, settings: Settings) -> CalibrationArtifact:
    """The station's declared region (gates.projection_region other than the default auto) recorded as px
    vertices, so lint judges fold-over over it as well as over the observed corners (a robot that looks there
    needs the model one-to-one there); a region that is not one of this image: UsageError naming it (exit
    2)."""
    if settings.gates.projection_region.strip().lower() == "auto" or art.image_size is None:
        return art
    size = (int(art.image_size[0]), int(art.image_size[1]))
    circle = facts_from_document(
        art.model_dump(mode="json", include={"gates", "camera_matrix"}), art.serial
    ).image_circle
    vertices = station_region(settings, size, circle).vertices_px(size)
    return art.model_copy(update={"required_region_px": [(float(u), float(v)) for u, v in vertices]})


def _rejected_corners(session: CaptureSession, rejection: CornerRejection) -> list[RejectedCorner]:
    return [
        RejectedCorner(
            view=session.views[c.view_index].name,
            corner_id=c.corner_id,
            residual_px=c.residual_px,
            dx_px=c.dx_px,
            dy_px=c.dy_px,
        )
        for c in rejection.rejected
    ]


def build_artifact(
    session: CaptureSession,
    request: SolveRequest,
    settings: Settings,
    board_gauge: tuple[str, str] | None = None,
) -> tuple[CalibrationArtifact, list]:
    """Solve, validate and lint one session; the artifact is unsealed (the store allocates the version).
    ``board_gauge``: lint's fact of a failed gauge on the session's board revision (``board_gauge_fact``)."""
    early = _EARLY.take(_numbers_key(session, request)) if len(_EARLY) else None
    if early is not None:  # started while the session was written (start_numbers); its error is raised here
        n: SolveNumbers = early.result()
    else:
        with verdict_lanes(settings.jobs) as lanes:
            n = _solve_numbers(session, request, lanes)
    model = get_model(n.model_name)
    free = [p for p in model.free_intrinsics] + list(model.free_distortion)
    art = CalibrationArtifact(
        serial=session.serial,
        version=1,
        status="accepted",
        image_size=session.image_size,
        camera_matrix=tuple(tuple(float(x) for x in row) for row in n.solution.camera_matrix),
        dist_coeffs=[float(x) for x in n.solution.dist_coeffs],
        model=DistortionModelInfo(
            name=n.model_name,
            opencv_flags=int(model.flags),
            flag_names=flag_names(int(model.flags)),
            free_parameters=free,
            selection=n.trail,
        ),
        stdev=Uncertainty(
            sigma={k: float(v) for k, v in n.solution.sigma.items()},
            refused_reason=n.solution.sigma_refused_reason,
            residual_count=int(n.solution.n_residuals),
            parameter_count=int(n.solution.n_parameters),
            covariance=_covariance(n.solution),
            view_level=_view_level(n.solution),
        ),
        rms_px=float(n.solution.rms_px),
        detector_rms_px=n.detector_rms,
        held_out=_held_out(n.holdout),
        gates=_gates(session, request),
        board=session.board,
        views=_views(session, n.solution, n.first, n.outliers, n.kept, n.dropped),
        rejected_corners=_rejected_corners(session, n.rejection),
        observed_region_px=_observed_region(
            n.rejection.kept([np.asarray(v.corners_px, np.float64) for v in session.views])
        ),
        camera_consistency=n.consistency,
        camera_change=n.change,
        provenance=Provenance(
            calibctl_version=__version__,
            opencv_version=cv2.__version__,
            station=settings.station,
            operator=settings.operator,
            created_at=utc_now(),
            session_id=session.session_id,
            input_image_sha256=sorted({v.image_sha256 for v in session.views if v.image_sha256}),
            gauge_override=request.override_gauge,
        ),
        metric_gauge=session.metric_gauge,
        content_sha256=UNSEALED,
    )
    art = _with_required_region(art, settings)
    facts = facts_from_document(art.model_dump(mode="json"), art.serial)
    facts.board_gauge = board_gauge
    findings = lint_facts(facts, settings.lint)
    status = "rejected" if has_errors(findings) else "accepted"
    corner_outliers = [
        {
            "view": session.views[c.view_index].name,
            "corner_id": c.corner_id,
            "residual_px": c.residual_px,
        }
        for c in n.outliers.outlier_corners
    ]
    return art.model_copy(update={"lint": findings, "status": status}), corner_outliers


def checked_override(reason: str | None) -> str | None:
    """--override-gauge's reason, stripped (UsageError when it is given empty)."""
    if reason is None:
        return None
    if not reason.strip():
        raise UsageError(
            "--override-gauge needs a reason",
            "say why the failed metric gauge does not apply, e.g. "
            "--override-gauge 'fixture moved; board re-measured 2026-11-27 (25.02 mm)'",
        )
    return reason.strip()


def _check_gauge_override(
    session: CaptureSession, reason: str | None, board_gauge: tuple[str, str] | None
) -> None:
    """An override must have a failed gauge to override (the session's own, or one of its board revision):
    anything else is a usage error, nothing stored."""
    gauge = session.metric_gauge
    if reason is not None and (gauge is None or gauge.distance.passed) and board_gauge is None:
        what = "has no metric gauge" if gauge is None else "passed its metric gauge"
        raise UsageError(
            f"--override-gauge: session {session.session_id} {what} and its board {session.board.ref} "
            "has no failed one; there is nothing to override",
            "leave --override-gauge out",
        )


def solve(settings: Settings, request: SolveRequest) -> SolveOutcome:
    if request.model not in MODEL_CHOICES:
        raise UsageError(f"unknown model '{request.model}'", f"choose one of {', '.join(MODEL_CHOICES)}")
    request = replace(request, override_gauge=checked_override(request.override_gauge))
    if not request.session_id and not request.serial:
        raise UsageError("name a session", "pass SESSION_ID or --serial SERIAL")
    if request.report_dir is not None:
        # only with --report: a plain solve does not load the HTML and SVG writers
        from calibctl.workflows.report import report as report_workflow

        report_workflow.ready_folder(request.report_dir)
    report_path = version = None
    with open_store(settings, write=True) as store:
        session = (
            store.get_session(request.session_id)
            if request.session_id
            else store.latest_session(request.serial or "")
        )
        if request.session_id and request.serial and session.serial != request.serial:
            raise UsageError(
                f"session {session.session_id} is of camera {session.serial}, not {request.serial}",
                "name the session alone, or the serial alone (its latest accepted session)",
            )
        if session.status != "accepted":
            failed = ", ".join(g.gate for g in session.gates if not g.passed) or "capture gates"
            raise UsageError(
                f"session {session.session_id} was rejected at capture ({failed}); it cannot be solved",
                "capture again following the gate hints, then solve the new session",
            )
        board_gauge = board_gauge_fact(
            session.board.ref, session.session_id, board_failures(store, session.board.ref)
        )
        _check_gauge_override(session, request.override_gauge, board_gauge)
        if request.report_dir is not None:  # the page of the version about to be stored must be free
            version = store.next_version(session.serial)
            report_path = report_workflow.ready_page(request.report_dir, session.serial, version)
        art, corner_outliers = build_artifact(session, request, settings, board_gauge)
        activate = request.activate and art.status == "accepted"
        stored = store.add_artifact(
            art,
            activate=activate,
            actor=settings.operator,
            station=settings.station,
            reason=f"solve of session {session.session_id}",
            expect_version=version,  # with --report: the version whose page was checked, or nothing stored
        )
        # not read back: a new version is active exactly when its activation event was written with it
        active = activate
    if report_path is not None:
        report_workflow.write_report(settings, stored.ref, report_path, force=False)
    return SolveOutcome(
        artifact=stored, active=active, outlier_corners=corner_outliers, report_path=report_path
    )
