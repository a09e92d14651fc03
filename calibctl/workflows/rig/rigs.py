"""Rig use cases on the store: register a rig, capture it, solve it into the rig's next version.

- ``add_rig``: members must be serials the store knows (a calibration exists), each once; design
  baselines are ``A:B=75.0+-0.5`` (mm); ``frames`` are non-camera frames hand-eye edges may join. One
  camera is a rig too: the root of a tree of sensor edges (camera-IMU, camera-LiDAR, hand-eye).
- ``capture_rig``: one ordinary capture per camera (today's detection, outcomes and gates, stored as
  that camera's session), then the images are paired into frames by the last number in their names
  (core.extrinsics.rig_frames) and the ``rig-connected`` gate decides the rig session's status.
- ``solve_rig_stored``: member intrinsics from each camera's ACTIVE calibration (fixed, their sigmas
  carried into the extrinsics' covariance as a diagonal: the artifact keeps sigmas, not the full
  covariance), or refined jointly; the solve, held-out numbers, loop closure and rig lint; stored as
  the rig's next version, accepted and active when lint passes, rejected otherwise. A one-camera rig has
  nothing to capture or solve: its version pins the member's active calibration (no edge, no pair), and the
  commands that need two cameras refuse it (``refuse_single``, exit 2).
"""

from __future__ import annotations

import secrets
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibctl import __version__
from calibctl.artifacts.calibration import CalibrationArtifact, Provenance
from calibctl.artifacts.common import parse_document, utc_now
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.artifacts.rig import (
    UNSEALED,
    RigCalibration,
    RigDefinition,
    RigEdge,
    RigFrame,
    RigGate,
    RigMember,
    RigSession,
    UnmatchedImage,
)
from calibctl.artifacts.session import CaptureSession
from calibctl.config import Settings
from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics import rig_identity as identity
from calibctl.core.extrinsics.rig_frames import MIN_SHARED_VIEWS, match_frames, rig_connected_gate
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_validation import loop_closures, validate_rig_holdout
from calibctl.core.intrinsics.covariance import intrinsic_columns
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.solve import FISHEYE_DIST_NAMES, MODELS
from calibctl.errors import InputError, NotFoundError, UsageError
from calibctl.store.gauge_failures import GaugeFailure
from calibctl.workflows.board.boards import board_ref
from calibctl.workflows.board.gauge_failures import board_failures, check_override, failure_fix, failure_text
from calibctl.workflows.camera.capture import CaptureRequest, CaptureResult, capture
from calibctl.workflows.camera.distance_gauge import RATIO_LIMITS
from calibctl.workflows.camera.solve import checked_override
from calibctl.workflows.edges.versions import cal_versions, carried_forward
from calibctl.workflows.rig import rig_video
from calibctl.workflows.rig.rig_folders import RigGauge, check_min_shared_views, rig_loops, rig_pairs
from calibctl.workflows.rig.rig_lint import parse_design, rig_findings
from calibctl.workflows.store_admin.records import open_store

PINNED_SOLVER = "pinned: one camera, its active calibration"  # RigCalibration.solver of a one-camera rig


@dataclass(frozen=True)
class RigCaptureResult:
    session: RigSession
    cameras: Mapping[str, CaptureResult]

    @property
    def passed(self) -> bool:
        return self.session.status == "accepted"


@dataclass(frozen=True)
class RigSolveOutcome:
    calibration: RigCalibration
    active: bool


def add_rig(
    settings: Settings,
    name: str,
    cameras: Sequence[str],
    root: str | None,
    designs: Sequence[str],
    frames: Sequence[str] = (),
) -> RigDefinition:
    """Register a rig (see module docstring)."""
    seen = [c for i, c in enumerate(cameras) if c in cameras[:i]]
    if seen:
        raise UsageError(f"camera {seen[0]} is listed twice", hint="name each camera of the rig once")
    if not cameras:
        raise UsageError("a rig needs at least one camera", hint="pass --camera per member")
    if len(cameras) == 1 and designs:
        raise UsageError(
            f"rig {name} has one camera: a design baseline is the distance between two",
            hint="leave --design-baseline-mm out, or add the other camera with a second --camera",
        )
    root = root or cameras[0]
    if root not in cameras:
        raise UsageError(f"--root {root} is not one of the cameras ({', '.join(cameras)})")
    with open_store(settings, write=True) as store:  # signed with the configured key, like every record
        known = set(store.serials())
        unknown = [c for c in cameras if c not in known]
        captured = [c for c in unknown if store.list_sessions(c)]
        if captured:  # "unknown camera" misleads when the store holds its (e.g. gate-rejected) captures
            raise NotFoundError(
                f"camera(s) {', '.join(captured)} have capture sessions but no calibration yet",
                hint="solve an accepted session of each (`calibctl solve --serial ...`), or capture "
                "again following the gate hints; a rig is solved from calibrated members",
            )
        if unknown:
            raise NotFoundError(
                f"unknown camera(s) {', '.join(unknown)}: the store has no calibration for them",
                hint="calibrate each member first (`calibctl calibrate --serial ...`)",
            )
        doc = parse_document(
            RigDefinition,
            {
                "name": name,
                "cameras": list(cameras),
                "root": root,
                "design_baselines": [parse_design(d).model_dump() for d in designs],
                "frames": list(frames),
                "created_at": utc_now(),
                "created_by": settings.operator,
                "station": settings.station,
            },
            f"rig {name}",
        )
        return store.add_rig(doc)


def capture_rig(
    settings: Settings,
    rig_name: str,
    sources: Mapping[str, str],
    board: str,
    min_shared_views: int = MIN_SHARED_VIEWS,
    gauge: RigGauge | None = None,
    override_gauge: str | None = None,
    timestamps: Path | None = None,
    time_tolerance_ms: float | None = None,
) -> RigCaptureResult:
    """Capture every member, pair the images into frames (by the last number in their names, or with the
    recorder's ``timestamps`` by time within ``time_tolerance_ms``: workflows.rig.rig_video), apply the rig
    gate and the metric gauge (the board revision's failed gauges, and ``gauge`` when given: judged through
    that member's session, as ``capture --reference-distance`` does); store the rig session."""
    check_min_shared_views(min_shared_views)
    if timestamps is None and time_tolerance_ms is not None:
        raise UsageError(
            "--time-tolerance-ms pairs frames by time: give the recorder's --timestamps",
            hint="photos without timestamps pair up by the last number in their names",
        )
    if timestamps is not None:
        videos = [c for c, src in sources.items() if rig_video.is_timed({c: Path(src)}, None)]
        if videos:
            raise UsageError(
                f"rig capture pairs photos by time, but the source of {', '.join(videos)} is a video",
                hint="solve a rig recorded as videos with `calibctl rig solve-folders --timestamps`, or "
                "extract the frames to a folder per camera",
            )
    override_gauge = checked_override(override_gauge)
    with open_store(settings) as store:
        rig = store.get_rig(rig_name)
        refuse_single(rig, "rig capture pairs the images of two or more cameras")
        board_rev = store.get_board(*board_ref(board))
        failures = board_failures(store, board_rev.ref)
    if gauge is not None and gauge.camera not in rig.cameras:
        raise UsageError(
            f"--reference-source names {gauge.camera}, not a camera of rig {rig.name}",
            f"give the fixture pictures of one member: --reference-source SERIAL=FOLDER, SERIAL one of "
            f"{', '.join(rig.cameras)}",
        )
    if gauge is None:
        check_override(override_gauge, board_rev.ref, failures, f"rig {rig.name} capture")
    extra = [c for c in sources if c not in rig.cameras]
    missing = [c for c in rig.cameras if c not in sources]
    if extra or missing:
        raise UsageError(
            f"rig {rig.name} has cameras {', '.join(rig.cameras)}; "
            + (f"unknown: {', '.join(extra)}" if extra else f"no --source for {', '.join(missing)}"),
            hint="pass one --source SERIAL=FOLDER per member",
        )
    results = {
        c: capture(settings, _member_request(c, board_rev.ref, sources[c], gauge), store_session=False)
        for c in rig.cameras
    }
    failures += [
        GaugeFailure(
            board_rev.ref, c, f"session {r.session.session_id}", d.ratio, d.recovered_m, d.reference_m
        )
        for c, r in results.items()
        if (d := r.distance) is not None and not d.passed
    ]
    identity.refuse(
        identity.shared_images({c: [v.image_sha256 for v in r.session.views] for c, r in results.items()}),
        f"rig {rig.name} capture",
    )
    names = {c: [o.name for o in r.session.outcomes] for c, r in results.items()}
    if timestamps is not None:
        tolerance = rig_video.DEFAULT_TIME_TOLERANCE_MS if time_tolerance_ms is None else time_tolerance_ms
        match, _ = rig_video.pair_images_by_time(names, timestamps, tolerance)
        if not match.frames:
            raise InputError(
                f"no images of different cameras lie within {tolerance:g} ms of each other, so nothing "
                "pairs up",
                hint="check that the timestamps belong to these images, or widen --time-tolerance-ms",
            )
    else:
        match = match_frames(names)
    if not match.frames:
        raise InputError(
            "no images of different cameras share a frame number, so nothing pairs up",
            hint="name the images so that the last number in the name is the frame number or "
            "timestamp, the same for images taken together (left_0042.png / right_0042.png)",
        )
    with_views = {c: {v.name for v in r.session.views} for c, r in results.items()}
    cams = list(rig.cameras)
    counts = {
        (a, b): sum(
            1
            for _, imgs in match.frames
            if imgs.get(cams[a]) in with_views[cams[a]] and imgs.get(cams[b]) in with_views[cams[b]]
        )
        for a in range(len(cams))
        for b in range(a + 1, len(cams))
    }
    g = rig_connected_gate(cams, counts, min_shared_views)
    gate = RigGate(
        gate="rig-connected",
        passed=g.passed,
        value=g.value,
        threshold=g.threshold,
        message=g.message,
        hint=g.hint,
    )
    gates = [gate, *_gauge_gate(board_rev.ref, failures, override_gauge)]
    session = RigSession(
        rig_session_id=secrets.token_hex(6),
        rig=rig.name,
        camera_sessions={c: r.session.session_id for c, r in results.items()},
        frames=[RigFrame(key=k, images=dict(imgs)) for k, imgs in match.frames],
        # the stored record keeps the reason's code, not the time distances after it
        unmatched=[
            UnmatchedImage(camera=u.camera, name=u.path, reason=u.reason.partition(":")[0])
            for u in match.unmatched
        ],
        shared_views={f"{cams[a]}-{cams[b]}": n for (a, b), n in counts.items()},
        gates=gates,
        status="accepted" if all(x.passed for x in gates) else "rejected",
        created_at=utc_now(),
        station=settings.station,
        operator=settings.operator,
    )
    identity.refuse(
        identity.same_corners(
            _session_views(list(rig.cameras), session, {c: r.session for c, r in results.items()})
        ),
        f"rig {rig.name} capture",
    )
    with open_store(
        settings, write=True
    ) as store:  # every member's session and the rig session, or none; signed
        store.add_rig_session(session, [results[c].session for c in rig.cameras])
    return RigCaptureResult(session, results)


def refuse_single(rig: RigDefinition, why: str) -> None:
    """UsageError (exit 2) for a one-camera rig where ``why`` needs two cameras."""
    if len(rig.cameras) == 1:
        raise UsageError(
            f"rig {rig.name} has one camera ({rig.root}): {why}",
            hint=f"`calibctl rig solve {rig.name}` pins its calibration for IMU and LiDAR edges; register "
            "a rig of two or more cameras (`calibctl rig add`) for camera-camera extrinsics",
        )


def session_gauge_findings(
    board: str, failures: Sequence[GaugeFailure], gates: Sequence[RigGate]
) -> list[Finding]:
    """``metric-gauge`` of the rig session's board revision: an error when it has a failed gauge the rig
    capture did not override (a session captured before the gauge failed, or before this gate existed)."""
    overridden = any(g.gate == "metric-gauge" and g.passed for g in gates)
    if not failures or overridden:
        return []
    return [
        Finding(
            rule="metric-gauge",
            severity="error",
            message=f"the rig session's {failure_text(board, failures)}",
            fix=failure_fix(board, "`calibctl rig capture ... --override-gauge REASON`"),
        )
    ]


def _member_request(camera: str, board: str, source: str, gauge: RigGauge | None) -> CaptureRequest:
    if gauge is None or gauge.camera != camera:
        return CaptureRequest(serial=camera, board=board, source=source)
    return CaptureRequest(
        serial=camera,
        board=board,
        source=source,
        reference_distance=gauge.reference,
        reference_source=gauge.fixture,
    )


def _gauge_gate(board: str, failures: Sequence[GaugeFailure], override: str | None) -> list[RigGate]:
    """The rig's ``metric-gauge`` gate: failed when the board revision has a failed gauge (stored, or this
    capture's), passed with the override's reason recorded; no gate when there is nothing to judge."""
    if not failures:
        return []
    message = failure_text(board, failures)
    return [
        RigGate(
            gate="metric-gauge",
            passed=override is not None,
            value=abs(failures[0].ratio - 1.0),
            threshold=RATIO_LIMITS[1] - 1.0,
            message=message if override is None else f"{message}; overridden: {override}",
            hint=None if override is not None else failure_fix(board),
        )
    ]


def member_intrinsics(art: CalibrationArtifact) -> MemberIntrinsics:
    """A member's active calibration as the rig solve uses it (its sigmas as a diagonal covariance)."""
    model = MODELS.get(art.model.name)
    free_int = tuple(model.free_intrinsics) if model else ("fx", "fy", "cx", "cy")
    free_dist = tuple(model.free_distortion) if model else ()
    lens = "fisheye" if model is not None and model.kind == "fisheye" else "pinhole"
    K = np.array(art.camera_matrix, dtype=np.float64)
    aspect = float(K[0, 0] / K[1, 1]) if (model is None or model.fx_tied_to_fy) else None
    _, names = intrinsic_columns(
        np.zeros((2, 18)), free_int, free_dist, aspect, FISHEYE_DIST_NAMES if lens == "fisheye" else None
    )
    sig = art.stdev.sigma
    cov = np.diag([sig[n] ** 2 for n in names]) if all(n in sig for n in names) else None
    return MemberIntrinsics(
        art.serial,
        K,
        np.array(art.dist_coeffs, dtype=np.float64),
        art.image_size,
        free_int,
        free_dist,
        aspect,
        cov,
        lens,
    )


def rig_member(art: CalibrationArtifact, used: MemberIntrinsics, refined: bool) -> RigMember:
    """The member ``art`` pinned with the intrinsics the solve ``used`` (refined or as stored)."""
    return RigMember(
        serial=art.serial,
        version=art.version,
        content_sha256=art.content_sha256,
        image_size=art.image_size,
        camera_matrix=tuple(map(tuple, np.asarray(used.camera_matrix).tolist())),
        dist_coeffs=np.asarray(used.dist_coeffs).tolist(),
        refined=refined,
        lens="fisheye" if used.lens == "fisheye" else "pinhole",
    )


def _session_views(
    order: Sequence[str], session: RigSession, cam_sessions: Mapping[str, CaptureSession]
) -> RigViews:
    """The rig session's frames as RigViews over the members' stored corners."""
    from calibctl.workflows.board.boards import board_spec

    spec = board_spec(cam_sessions[order[0]].board)
    by_name = {c: {v.name: v for v in s.views} for c, s in cam_sessions.items()}
    rows = []
    for frame in session.frames:
        row: list[BoardView | None] = []
        for c in order:
            v = by_name[c].get(frame.images.get(c, ""))
            row.append(BoardView(v.name, np.array(v.corner_ids), np.array(v.corners_px)) if v else None)
        rows.append(tuple(row))
    return RigViews(
        tuple(order), spec.object_points(), tuple(str(f.key) for f in session.frames), tuple(rows)
    )


def _views(
    rig: RigDefinition, order: Sequence[str], session: RigSession, store: object
) -> tuple[RigViews, dict[str, CaptureSession]]:
    cam_sessions = {c: store.get_session(session.camera_sessions[c]) for c in order}  # type: ignore[attr-defined]
    return _session_views(order, session, cam_sessions), cam_sessions


def solve_rig_stored(
    settings: Settings,
    rig_name: str,
    rig_session_id: str | None = None,
    refine_intrinsics: bool = False,
    model: str = DEFAULT_MODEL,
    activate: bool = True,
) -> RigSolveOutcome:
    """Solve a stored rig session into the rig's next version (see module docstring)."""
    with open_store(settings, write=True) as store:
        rig = store.get_rig(rig_name)
        if len(rig.cameras) == 1:
            return _pin_single(settings, store, rig, rig_session_id, refine_intrinsics, activate)
        session = store.get_rig_session(rig.name, rig_session_id)
        order = [rig.root, *[c for c in rig.cameras if c != rig.root]]
        arts = _active_members(store, order)
        views, cam_sessions = _views(rig, order, session, store)
        for c in order:
            size = cam_sessions[c].image_size
            if size is not None and tuple(size) != tuple(arts[c].image_size):
                raise InputError(
                    f"rig member {c}: the capture is {size[0]}x{size[1]} but its calibration "
                    f"{arts[c].ref} is {arts[c].image_size[0]}x{arts[c].image_size[1]}",
                    hint="capture at the calibrated resolution, or re-calibrate the camera",
                )
        what = f"rig {rig.name} session {session.rig_session_id}"
        identity.refuse(
            identity.shared_images({c: [v.image_sha256 for v in cam_sessions[c].views] for c in order})
            + identity.same_corners(views),
            what,
        )  # a session stored before these checks existed
        members = [member_intrinsics(arts[c]) for c in order]
        solution = solve_rig(views, members, refine_intrinsics, model)
        holdout = validate_rig_holdout(views, members, refine_intrinsics, model)
        loops = loop_closures(views, members, model) if len(order) >= 3 else ()
        cal = RigCalibration(
            rig=rig.name,
            version=1,
            status="accepted",
            root=rig.root,
            members=[
                rig_member(arts[c], m, refine_intrinsics)
                for c, m in zip(order, solution.members, strict=True)
            ],
            edges=[
                RigEdge(
                    parent=e.parent,
                    child=e.child,
                    T_parent_child=tuple(map(tuple, e.T_parent_child.tolist())),
                    covariance=e.covariance.tolist(),
                    translation_mm=e.translation_mm,
                    sigma_translation_mm=e.sigma_translation_mm,
                    rotation_deg=e.rotation_deg,
                    sigma_rotation_deg=e.sigma_rotation_deg,
                )
                for e in solution.tree.edges
            ],
            pairs=rig_pairs(solution, holdout),
            loops=rig_loops(loops),
            fit_rms_px=dict(zip(order, solution.rms_px, strict=True)),
            held_out_rms_px=dict(zip(order, holdout.camera_rms_px, strict=True)),
            held_out_folds=holdout.n_folds,
            solver=solution.solver,
            refine_intrinsics=refine_intrinsics,
            gates=session.gates,
            provenance=Provenance(
                calibctl_version=__version__,
                opencv_version=cv2.__version__,
                station=settings.station,
                operator=settings.operator,
                created_at=utc_now(),
                session_id=session.rig_session_id,
            ),
            content_sha256=UNSEALED,
        )
        identity.refuse(identity.zero_baselines(identity.pair_translations(solution)), what)
        board = cam_sessions[order[0]].board.ref
        return _store_solved(settings, store, rig, cal, arts, activate, (board, session.gates))


def _active_members(store: Any, order: Sequence[str]) -> dict[str, CalibrationArtifact]:
    arts: dict[str, CalibrationArtifact] = {}
    for c in order:
        try:
            arts[c] = store.get_artifact(c, None)
        except NotFoundError as exc:
            raise NotFoundError(
                f"rig member {c} has no active calibration ({exc.message})",
                hint=f"calibrate {c} (or roll it back to an accepted version) and solve again",
            ) from exc
    return arts


def _pin_single(
    settings: Settings,
    store: Any,
    rig: RigDefinition,
    rig_session_id: str | None,
    refine_intrinsics: bool,
    activate: bool,
) -> RigSolveOutcome:
    """A one-camera rig's next version: no camera-camera edge to solve, so its member's active calibration
    is pinned as it is (the version sensor edges, IMU or LiDAR, are stored on)."""
    if rig_session_id is not None or refine_intrinsics:
        raise UsageError(
            f"rig {rig.name} has one camera: its solve pins {rig.root}'s active calibration, "
            + ("no rig session to solve" if rig_session_id is not None else "nothing to refine jointly"),
            hint=f"run `calibctl rig solve {rig.name}` alone (re-calibrate {rig.root} to change its "
            "intrinsics)",
        )
    arts = _active_members(store, [rig.root])
    art = arts[rig.root]
    cal = RigCalibration(
        rig=rig.name,
        version=1,
        status="accepted",
        root=rig.root,
        members=[rig_member(art, member_intrinsics(art), refined=False)],
        edges=[],
        pairs=[],
        fit_rms_px={art.serial: art.rms_px},
        held_out_rms_px={} if art.held_out.rms_px is None else {art.serial: art.held_out.rms_px},
        held_out_folds=art.held_out.k_folds,
        solver=PINNED_SOLVER,
        refine_intrinsics=False,
        provenance=Provenance(
            calibctl_version=__version__,
            opencv_version=cv2.__version__,
            station=settings.station,
            operator=settings.operator,
            created_at=utc_now(),
        ),
        content_sha256=UNSEALED,
    )
    return _store_solved(settings, store, rig, cal, arts, activate, None)


def _store_solved(
    settings: Settings,
    store: Any,
    rig: RigDefinition,
    cal: RigCalibration,
    arts: Mapping[str, CalibrationArtifact],
    activate: bool,
    session_board: tuple[str, Sequence[RigGate]] | None,
) -> RigSolveOutcome:
    """Lint ``cal`` (the members' rules, and the rig session's board gauge when it has one), keep the active
    version's evidence edges, store it as the rig's next version; active when accepted and asked."""
    boards = [session_board[0]] if session_board is not None else []
    gauges = store.failed_gauges([*boards, *(a.board.ref for a in arts.values())])
    findings = rig_findings(cal, rig, dict(arts), settings.lint, gauges)
    if session_board is not None:
        board, gates = session_board
        findings += session_gauge_findings(board, gauges.get(board, []), gates)
    cal = cal.model_copy(
        update={"lint": findings, "status": "rejected" if has_errors(findings) else "accepted"}
    )
    cal, base = _with_carried_handeye(cal, store)
    do_activate = activate and cal.status == "accepted"
    stored = store.add_rig_calibration(
        cal,
        activate=do_activate,
        actor=settings.operator,
        station=settings.station,
        reason="rig solve",
        based_on=base,
    )
    return RigSolveOutcome(stored, do_activate)


def _with_carried_handeye(cal: RigCalibration, store: object) -> tuple[RigCalibration, int | None]:
    """Keep the active version's hand-eye and LiDAR edges (not the stale ones) in the re-solved tree; and that
    version (None: nothing active), which the store compares-and-sets on (workflows.edges)."""
    try:
        active = store.get_rig_calibration(cal.rig, None)  # type: ignore[attr-defined]
    except NotFoundError:
        return cal, None
    kept = carried_forward(active, cal_versions(store, active))
    carried = cal.model_copy(
        update={
            "edges": [*cal.edges, *kept.edges],
            **kept.evidence,
            "lint": [*cal.lint, *kept.dropped],
        }
    )
    return carried, active.version
