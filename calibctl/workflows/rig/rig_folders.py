"""``calibctl rig solve-folders``: a camera rig solved from per-camera photo folders, no store needed.

Steps: list each camera's photos (a folder, a quoted glob or a list file, resolved as ``capture --source``
and ``rig capture`` resolve them: workflows.camera.capture_sources); match them into synchronised frames by
frame key (the last run of digits in the file name: core.extrinsics.rig_frames); detect and classify every
photo with today's per-image outcomes; calibrate each camera on its own accepted photos
(core.intrinsics.solve, full covariance) unless its intrinsics are given; the ``rig-connected`` gate; the rig
solve (core.extrinsics), k-fold held-out numbers and, for three or more cameras, pairwise loop closure.

Then the verdict the stored path gives (``rig solve`` stores it as the version's lint): the rig lint
rules that need no store (workflows.rig.rig_lint.solved_rig_findings: ``baseline-design`` against
``--design-baseline-mm``, ``epipolar``, ``loop-closure``), each self-calibrated member judged as the stored
path judges it, capture gates and calibration lint (workflows.rig.rig_members, which says the rules it cannot
apply and why), ``rig-rigid`` when the frames contradict each other (core InconsistentDataError: not rigid or
not synchronised), and for frames paired by time ``rig-frame-shift`` when a camera's frames fit the others' a
whole frame off, else ``rig-exposure-offset`` for a pair exposed further apart than its times say
(workflows.rig.rig_video). ``rig-stale-member`` needs the store: there is no stored member to go stale.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TypeVar

import numpy as np

from calibctl.artifacts.lint import Finding, has_errors
from calibctl.artifacts.rig import DesignBaseline, RigLoop, RigPair
from calibctl.config import LintThresholds, Settings, load_settings
from calibctl.core.board.board_spec import CHESSBOARD, BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture.image_outcomes import NEAR_DUPLICATE, UNREADABLE, ImageOutcome
from calibctl.core.extrinsics import rig_identity as identity
from calibctl.core.extrinsics.rig_frame_shift import ESTIMATE_STEP_MS, median_interval_s, offset_minimum
from calibctl.core.extrinsics.rig_frames import (
    MAX_MIN_SHARED_VIEWS,
    MIN_SHARED_VIEWS,
    FrameMatch,
    match_frames,
    rig_connected_gate,
)
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.extrinsics.rig_solve import RigSolution, solve_rig
from calibctl.core.extrinsics.rig_tree import sigma_rotation_deg, sigma_translation_mm
from calibctl.core.extrinsics.rig_uncertainty import rig_covariance
from calibctl.core.extrinsics.rig_validation import (
    LoopClosure,
    RigHoldout,
    loop_closures,
    validate_rig_holdout,
)
from calibctl.core.extrinsics.se3 import rotation_angle_deg
from calibctl.core.gate import GateResult
from calibctl.core.intrinsics import model_fit
from calibctl.core.intrinsics.model_names import DEFAULT_MODEL
from calibctl.core.intrinsics.model_select import select_model
from calibctl.core.intrinsics.solve import get_model, solve_intrinsics
from calibctl.errors import CalibctlError, InconsistentDataError, InputError, NumericalError, UsageError
from calibctl.files import file_errors
from calibctl.workflows.camera import capture_sources
from calibctl.workflows.camera.capture import classify_photos, refuse_another_pattern
from calibctl.workflows.camera.distance_gauge import (
    ReferenceDistance,
    board_distances_m,
    detect_fixture_views,
    distance_reason,
    judge_distance,
)
from calibctl.workflows.lint.lint import adopt
from calibctl.workflows.rig import rig_video
from calibctl.workflows.rig.rig_lint import member_finding, solved_rig_findings
from calibctl.workflows.rig.rig_members import member_findings

T = TypeVar("T")
USABLE = ("accepted", NEAR_DUPLICATE)  # a still board is no new geometry for one camera, but a rig frame
SOURCE_HINT = "give SERIAL=FOLDER, SERIAL='glob' (quoted) or SERIAL=list.txt per camera"


@dataclass(frozen=True)
class MemberFit:
    """How well a self-calibrated member's own lens model explains its corners (lint's ``model-misfit``)."""

    model: str
    fit_rms_px: float
    detector_rms_px: float | None


PLAUSIBLE_SQUARE_MM = (
    5.0,
    300.0,
)  # printed calibration boards; outside it a unit or decimal typo is likelier


@dataclass(frozen=True)
class RigGauge:
    """The metric gauge of a rig capture or solve: ``camera``'s pictures of the board in a fixture at
    ``reference`` (``--reference-distance D+-S --reference-source SERIAL=SRC``)."""

    camera: str
    reference: ReferenceDistance
    fixture: str


@dataclass(frozen=True)
class RigFolderRun:
    """Everything ``solve-folders`` found; ``solution`` etc. are None when the gate failed or the frames
    contradict each other (then ``findings`` holds ``rig-rigid``)."""

    cameras: tuple[str, ...]
    match: FrameMatch
    outcomes: Mapping[str, Sequence[ImageOutcome]]
    views: RigViews
    members: tuple[MemberIntrinsics, ...]
    gate: GateResult
    solution: RigSolution | None = None
    holdout: RigHoldout | None = None
    loops: tuple[LoopClosure, ...] = ()
    fits: Mapping[str, MemberFit] | None = None
    findings: tuple[Finding, ...] = ()
    member_verdicts: Mapping[str, tuple[Finding, ...]] | None = None  # rig_members; None: model-misfit only
    designs: tuple[DesignBaseline, ...] = ()
    square_mm: float | None = None  # the board's square as given (the scale of every length)
    timing: Mapping[str, object] | None = None  # rig_video.timing_json when the frames were paired by time
    refused: tuple[Finding, ...] = ()  # members that could not be calibrated, left out of the rig

    @property
    def passed(self) -> bool:
        """The rig gate passed and the verdict has no error (exit 0)."""
        return self.gate.passed and not has_errors(list(self.findings))


def check_min_shared_views(n: int) -> None:
    """UsageError for a rig gate that links nothing (below 1) or nothing can meet."""
    if not 1 <= n <= MAX_MIN_SHARED_VIEWS:
        raise UsageError(
            f"--min-shared-views {n} is out of range (1 .. {MAX_MIN_SHARED_VIEWS})",
            f"the default is {MIN_SHARED_VIEWS} frames per linking pair",
        )


def parse_sources(items: Sequence[str], min_cameras: int = 2) -> dict[str, Path]:
    """['CAM=SRC', ...] -> {CAM: SRC}; UsageError on a malformed or repeated camera, or fewer than
    ``min_cameras`` (``rig capture`` passes 1: the registered rig says which cameras it needs)."""
    out: dict[str, Path] = {}
    for item in items:
        name, sep, folder = item.partition("=")
        if not sep or not name or not folder:
            raise UsageError(
                f"--source must look like SERIAL=FOLDER (or SERIAL='glob', SERIAL=list.txt), got {item!r}"
            )
        if name in out:
            raise UsageError(f"camera {name} is given twice", hint="name each camera of the rig once")
        out[name] = Path(folder)
    if len(out) < min_cameras:
        raise UsageError(
            f"a rig needs at least two cameras, got {len(out)}", hint="give one --source per camera"
        )
    return out


def _per_camera(items: Sequence[str], option: str, read: Callable[[str], T], expected: str) -> dict[str, T]:
    """``OPTION SERIAL=VALUE`` items -> {SERIAL: read(VALUE)}; ``read`` raises ValueError on a bad value."""
    out: dict[str, T] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            read_value = read(value)
        except ValueError:
            read_value = None
        if not sep or not name or read_value is None:
            raise UsageError(f"{option} {item}: expected {expected}")
        if name in out:
            raise UsageError(f"{option} names camera {name} twice")
        out[name] = read_value
    return out


def _finite_ms(value: str) -> float:
    ms = float(value)
    if not math.isfinite(ms):
        raise ValueError(value)
    return ms


def parse_exposure_offsets(items: Sequence[str]) -> dict[str, float]:
    """``--exposure-offset SERIAL=MS`` (MS a finite signed number of milliseconds) -> {SERIAL: MS}."""
    expected = "SERIAL=MS, MS the milliseconds that camera's frames were exposed after their listed times"
    expected += " (e.g. 0=-28)"
    return _per_camera(items, "--exposure-offset", _finite_ms, expected)


def parse_frame_shifts(items: Sequence[str]) -> dict[str, int]:
    """``--frame-shift SERIAL=N`` (N a whole number of frames, signed) -> {SERIAL: N}."""
    return _per_camera(items, "--frame-shift", int, "SERIAL=N, N a whole number of frames (e.g. 1=+1)")


def typed_spec(
    kind: str,
    cols: int,
    rows: int,
    square_mm: float,
    marker_mm: float | None = None,
    dictionary: str | None = None,
    inverted: bool = False,
    legacy: bool = False,
) -> BoardSpec:
    """The board as the command line types it (UsageError, exit 2, naming what is wrong)."""
    charuco = marker_mm is not None or dictionary is not None or inverted or legacy
    if kind == "chessboard" and charuco:
        raise UsageError(
            "--marker-mm, --dictionary, --inverted and --legacy describe a ChArUco board",
            "add --kind charuco",
        )
    if kind == "charuco" and (marker_mm is None or dictionary is None):
        raise UsageError("a ChArUco board needs --marker-mm and --dictionary (e.g. DICT_4X4_1000)")
    try:
        return BoardSpec(
            kind, cols, rows, square_mm / 1e3, None if marker_mm is None else marker_mm / 1e3, dictionary,
            legacy, inverted,
        )  # fmt: skip
    except ValueError as exc:
        raise UsageError(f"bad board: {exc}") from exc


def camera_photos(name: str, source: Path) -> tuple[capture_sources.SourceSpec, capture_sources.ImageSet]:
    """One camera's photos: a folder, glob or list as ``capture --source`` reads it; errors name the
    camera."""
    try:
        spec = capture_sources.resolve_source(str(source))
        if spec.kind not in capture_sources.IMAGE_SETS:
            raise InputError(f"--source {source} is a {spec.kind}; a rig is solved from photos", SOURCE_HINT)
        with file_errors(f"read the source {spec.kind}", spec.label):
            return spec, capture_sources.select_images(spec)
    except CalibctlError as exc:  # capture's hint for a missing source offers videos and cameras too
        hint = SOURCE_HINT if exc.hint == capture_sources.SOURCE_HINT else exc.hint
        raise type(exc)(f"camera {name}: {exc.message}", hint) from exc


def self_calibrated(
    name: str, outcomes: Sequence[ImageOutcome], spec: BoardSpec, model: str
) -> tuple[MemberIntrinsics, MemberFit]:
    """Calibrate one camera on its own accepted photos (core.intrinsics.solve, full covariance), and how well
    it fits."""
    views = [
        (Path(o.path).name, o.corner_ids, o.corners_px)
        for o in outcomes
        if o.accepted and o.corner_ids is not None and o.corners_px is not None
    ]
    size = next((o.image_size for o in outcomes if o.accepted and o.image_size), None)
    if size is None or not views:
        raise NumericalError(
            f"camera {name}: no photo with a detected board", hint="check the folder and the board"
        )
    points = spec.object_points()
    return calibrate_member(
        name,
        [points[ids] for _, ids, _ in views],
        [px for _, _, px in views],
        size,
        model,
        [n for n, _, _ in views],
    )


def calibrate_member(
    name: str,
    object_points: Sequence[np.ndarray],
    corners_px: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: str,
    view_names: Sequence[str] | None = None,
) -> tuple[MemberIntrinsics, MemberFit]:
    """One camera's intrinsics from its views (V arrays (N_i, 3) m and (N_i, 2) px) and its model fit;
    ``model`` "auto" chooses it for this camera by --model auto's rule (core.intrinsics.model_select).
    ``view_names`` (the photos' file names, as the rig's views name them) let the rig's frame-level covariance
    carry each photo's pull on these intrinsics (core.extrinsics.rig_uncertainty)."""
    if model == "auto":
        model = select_model(list(object_points), list(corners_px), image_size).chosen
    m = get_model(model)
    sol = solve_intrinsics(list(object_points), list(corners_px), image_size, m)
    ic = sol.covariance
    cov = ic.covariance if ic is not None else None
    pulls = None
    if ic is not None and cov is not None and ic.view_influences is not None and view_names is not None:
        pulls = dict(zip(view_names, ic.view_influences, strict=True))
    member = MemberIntrinsics(
        name,
        sol.camera_matrix,
        sol.dist_coeffs,
        image_size,
        m.free_intrinsics,
        m.free_distortion,
        sol.aspect_ratio,
        cov,
        m.kind,
        ic.jacobian_covariance if ic is not None and ic.inflated else None,
        pulls,
    )
    floor = model_fit.noise_floor_px(object_points, corners_px, image_size, float(sol.rms_px))
    return member, MemberFit(m.name, sol.rms_px, floor)


def rig_views(
    cameras: Sequence[str], match: FrameMatch, outcomes: Mapping[str, Sequence[ImageOutcome]], spec: BoardSpec
) -> RigViews:
    by_path = {o.path: o for name in cameras for o in outcomes[name]}
    rows, names = [], []
    for key, photos in match.frames:
        row: list[BoardView | None] = []
        for name in cameras:
            o = by_path.get(photos[name]) if name in photos else None
            usable = (
                o is not None and o.status in USABLE and o.corner_ids is not None and o.corners_px is not None
            )
            row.append(BoardView(Path(o.path).name, o.corner_ids, o.corners_px) if usable else None)  # type: ignore[arg-type,union-attr]
        rows.append(tuple(row))
        names.append(str(key))
    return RigViews(tuple(cameras), spec.object_points(), tuple(names), tuple(rows))


def solve_rig_folders(
    sources: Mapping[str, Path],
    spec: BoardSpec,
    model: str = DEFAULT_MODEL,
    intrinsics: Mapping[str, MemberIntrinsics] | None = None,
    refine_intrinsics: bool = False,
    min_shared_views: int = MIN_SHARED_VIEWS,
    workers: int | None = None,
    limits: LintThresholds | None = None,
    settings: Settings | None = None,
    designs: Sequence[DesignBaseline] = (),
    gauge: RigGauge | None = None,
    timestamps: Path | None = None,
    time_tolerance_ms: float = rig_video.DEFAULT_TIME_TOLERANCE_MS,
    frame_shifts: Mapping[str, int] | None = None,
    exposure_offsets_ms: Mapping[str, float] | None = None,
    estimate_offsets: Sequence[str] = (),
) -> RigFolderRun:
    """Run the folder flow (module docstring); a video per camera, or a ``timestamps`` file, pairs the frames
    by time within ``time_tolerance_ms`` instead (workflows.rig.rig_video; ``frame_shifts``: camera -> N
    whole frames its video is off its times, as declared, and ``rig-frame-shift`` names an undeclared one;
    ``exposure_offsets_ms``: camera -> ms its frames were exposed after their listed times, as declared, its
    corners interpolated to those times for the rig, and ``rig-exposure-offset`` names an undeclared one;
    ``estimate_offsets``: cameras whose offset is estimated from the data with its sd, then applied).
    The first source is the root
    camera; ``settings`` the station's (gates and lint; default: ``load_settings()``), ``limits`` its lint
    thresholds when given apart; ``designs`` the pairs' design baselines (``baseline-design``); ``gauge``:
    the metric gauge, judged through that camera's lens as the run leaves it (``metric-gauge``, seed
    chapter 0: the typed square size scales every baseline and no residual shows it).

    Raises:
        InputError, UsageError: a source is missing, holds no photos, is a video or camera, a glob or list
            mixes image sizes, a camera's photos differ in size from its intrinsics, or a design baseline
            names a camera that is not in the rig.
        NumericalError: a camera cannot be calibrated, or the rig solve fails on frames that agree.
    """
    check_min_shared_views(min_shared_views)
    if model != "auto":
        get_model(model)  # an unknown name is a usage error before any photo is read
    cameras = tuple(sources)
    if gauge is not None and gauge.camera not in cameras:
        raise UsageError(
            f"--reference-source names {gauge.camera}, not one of the cameras ({', '.join(cameras)})",
            "give the fixture pictures of one camera: --reference-source SERIAL=FOLDER",
        )
    for d in designs:
        if d.a not in cameras or d.b not in cameras or d.a == d.b:
            raise UsageError(
                f"--design-baseline-mm {d.a}:{d.b}: name two different cameras of the rig "
                f"({', '.join(cameras)})"
            )
    settings = settings or load_settings()
    if limits is not None:
        settings = settings.model_copy(update={"lint": limits})
    timed = None
    _check_estimates(estimate_offsets, cameras, exposure_offsets_ms or {})
    estimates = {name: 1.0 for name in estimate_offsets}
    for option, stated in (
        ("--frame-shift", frame_shifts),
        ("--exposure-offset", exposure_offsets_ms),
        ("--estimate-exposure-offset", estimates),
    ):
        if stated and not rig_video.is_timed(sources, timestamps):
            raise UsageError(
                f"{option} applies to frames paired by time: give videos or --timestamps",
                hint="photo folders pair by the last number in their names; rename the photos instead",
            )
    if rig_video.is_timed(sources, timestamps):
        offsets_s = {name: ms / 1e3 for name, ms in (exposure_offsets_ms or {}).items()}
        timed = rig_video.capture_timed(
            sources, spec, timestamps, time_tolerance_ms, workers, frame_shifts, offsets_s
        )
        match, outcomes = timed.match, {name: list(c.outcomes) for name, c in timed.cameras.items()}
        gathered = {name: (c.source, c.max_gray) for name, c in timed.cameras.items()}
    else:
        match, outcomes, gathered = _photo_frames(sources, spec, workers)
    if not match.frames and timed is None:
        raise InputError(
            "no photos of different cameras share a frame key, so nothing pairs up", hint=_NO_FRAMES_HINT
        )
    if not match.frames:
        raise InputError(
            f"no frames of different cameras lie within {time_tolerance_ms:g} ms of each other, so nothing "
            "pairs up",
            hint="check that the timestamps belong to these videos, or widen --time-tolerance-ms",
        )
    members, fits, refused = [], {}, {}
    for name in cameras:
        given = (intrinsics or {}).get(name)
        if given is None:
            try:
                member, fits[name] = self_calibrated(name, outcomes[name], spec, model)
            except NumericalError as exc:  # refused by name; the others go on if the rig stays connected
                refused[name] = exc
                continue
            members.append(member)
            continue
        sizes = {o.image_size for o in outcomes[name] if o.image_size is not None}
        if sizes and sizes != {tuple(given.image_size)}:
            found = ", ".join(f"{w}x{h}" for w, h in sorted(sizes))
            raise InputError(
                f"camera {name}: photos are {found} but its calibration is "
                f"{given.image_size[0]}x{given.image_size[1]}",
                hint="use the calibration made at this resolution, or re-calibrate the camera",
            )
        members.append(given)
    cameras, match, outcomes = _without(refused, cameras, match, outcomes)
    verdicts = {
        name: tuple(
            member_findings(settings, name, gathered[name][0], outcomes[name], gathered[name][1], spec, model)
        )
        for name in fits
    }
    if model == "auto":
        model = _auto_rig_model(fits, refine_intrinsics)
    if timed is not None and estimate_offsets:
        timed = _with_estimated_offsets(timed, cameras, members, spec, model, estimate_offsets)
    # a declared exposure offset moves that camera's corners for the rig alone; its lens keeps its frames
    views = rig_views(cameras, match, {n: rig_video.rig_outcomes(timed, n) if timed else outcomes[n]
                                       for n in cameras}, spec)  # fmt: skip
    identity.refuse(
        identity.shared_images(
            {n: [o.sha256 for o in outcomes[n] if o.corners_px is not None] for n in cameras}
        )
        + identity.same_corners(views),
        "rig solve-folders",
    )
    gate = rig_connected_gate(cameras, views.shared_view_counts(), min_shared_views)
    run = RigFolderRun(
        cameras,
        match,
        outcomes,
        views,
        tuple(members),
        gate,
        fits=fits,
        member_verdicts=verdicts,
        designs=tuple(designs),
        square_mm=spec.square_size_m * 1e3,
        timing=rig_video.timing_json(timed) if timed is not None else None,
        refused=tuple(refused_finding(name, exc) for name, exc in refused.items()),
    )
    shifted = []
    if timed is not None:
        shifted = rig_video.frame_shift_findings(timed, members, spec)
        # a whole frame off hides any fraction of one: the offsets are judged once the frames pair right
        shifted = shifted or rig_video.exposure_offset_findings(timed, members, spec)
    judged = replace(run, findings=(*run.findings, *shifted))
    if gate.passed:
        solved = judged_solve(run, model, refine_intrinsics, settings.lint)
        judged = replace(solved, findings=(*run.refused, *shifted, *solved.findings))
    if gauge is None:
        return judged
    if gauge.camera not in cameras:
        left_out = Finding(
            rule="metric-gauge",
            severity="error",
            message=f"{gauge.camera} was left out of the rig, so its fixture pictures could not be judged",
            fix="give the fixture pictures of a camera the rig keeps: --reference-source SERIAL=FOLDER",
        )
        return replace(judged, findings=(*judged.findings, left_out))
    i = cameras.index(gauge.camera)
    fit = fits.get(gauge.camera)
    finding = gauge_finding(gauge, spec, members[i], fit.model if fit else model, workers)
    return replace(judged, findings=(*judged.findings, *finding))


def gauge_finding(
    gauge: RigGauge, spec: BoardSpec, member: MemberIntrinsics, model: str, workers: int | None
) -> list[Finding]:
    """``metric-gauge`` of a folder rig: the fixture pictures' board distance through ``member``'s lens
    against the surveyed one (an error outside 0.99-1.01, nothing when it passes). CalibctlError (exit 2)
    when it cannot be judged (``distance_gauge.judge_distance``, ``detect_fixture_views``)."""
    source = capture_sources.resolve_source(gauge.fixture)
    views, _ = detect_fixture_views(
        spec, "the board", source, member.image_size, f"camera {gauge.camera}", workers
    )
    recovered = board_distances_m(spec, views, member.camera_matrix, member.dist_coeffs, model)
    d = judge_distance(gauge.reference, recovered, [v.name for v in views])
    if d.passed:
        return []
    return [
        Finding(
            rule="metric-gauge",
            severity="error",
            value=d.ratio,
            message=f"{gauge.camera}: {distance_reason(d)}: every baseline is scaled by it",
            fix="measure the squares (calipers and a long span) and give that --square-mm, or register the "
            "board (`calibctl board add`) and use `rig capture` + `rig solve`; check the fixture's surveyed "
            "distance",
        )
    ]


_NO_FRAMES_HINT = (
    "name the photos so that the last number in the name is the frame number or timestamp, the same for "
    "photos taken together (left_0042.png / right_0042.png)"
)
MEMBER_REFUSED = "rig-member-refused"


def _photo_frames(
    sources: Mapping[str, Path], spec: BoardSpec, workers: int | None
) -> tuple[
    FrameMatch, dict[str, list[ImageOutcome]], dict[str, tuple[capture_sources.SourceSpec, np.ndarray | None]]
]:
    """Photo folders paired by the last number in their names: the match, each camera's outcomes, and its
    source and half-size maximum."""
    sets = {name: camera_photos(name, source) for name, source in sources.items()}
    photos = {name: images.paths for name, (_, images) in sets.items()}
    same_files = {name: [str(Path(p).resolve()) for p in paths] for name, paths in photos.items()}
    identity.refuse(
        [
            replace(f, message=f.message.replace("identical image(s) (same sha256;", "of the same files ("))
            for f in identity.shared_images(same_files)
        ],
        "rig solve-folders",
    )  # before any detection
    match = match_frames(photos)
    if not match.frames:
        return match, {}, {}
    classified = {name: classify_photos(photos[name], spec, workers=workers) for name in sources}
    outcomes = {name: found for name, (found, _) in classified.items()}
    for name, (source, images) in sets.items():  # as capture: a glob or list of one size, a folder wrong_size
        mixed = capture_sources.mixed_sizes_error(
            source,
            {n: o.image_size for n, o in zip(images.names, outcomes[name], strict=True) if o.image_size},
        )
        if mixed is not None:
            raise InputError(f"camera {name}: {mixed.message}", mixed.hint)
        readable = [o for o in outcomes[name] if o.status != UNREADABLE]
        if readable and spec.kind == CHESSBOARD:  # the board given is the board seen (as capture checks)
            refuse_another_pattern(
                spec,
                f"--cols {spec.cols} --rows {spec.rows}",
                "",
                f"photos of camera {name}",
                readable,
                given="--cols/--rows",
            )
    return match, outcomes, {name: (sets[name][0], classified[name][1]) for name in sources}


def refused_finding(name: str, exc: CalibctlError) -> Finding:
    """A member that cannot be calibrated, named: the rest of the rig is solved without it."""
    return Finding(
        rule=MEMBER_REFUSED,
        severity="warning",
        message=f"{name} is left out of the rig: {exc.message}",
        fix=exc.hint or "capture more frames with the board well seen by this camera",
    )


def _without(
    refused: Mapping[str, CalibctlError],
    cameras: tuple[str, ...],
    match: FrameMatch,
    outcomes: Mapping[str, list[ImageOutcome]],
) -> tuple[tuple[str, ...], FrameMatch, dict[str, list[ImageOutcome]]]:
    """The rig without its refused members; the first refusal is raised when fewer than two cameras remain."""
    kept = tuple(name for name in cameras if name not in refused)
    if len(kept) < 2:
        raise next(iter(refused.values()))
    if not refused:
        return cameras, match, dict(outcomes)
    frames = []
    for key, photos in match.frames:
        left = {c: p for c, p in photos.items() if c in kept}
        if len(left) >= 2:
            frames.append((key, left))
    return kept, FrameMatch(tuple(frames), match.unmatched), {name: outcomes[name] for name in kept}


def _check_estimates(names: Sequence[str], cameras: Sequence[str], declared: Mapping[str, float]) -> None:
    for name in names:
        if name not in cameras:
            raise UsageError(
                f"--estimate-exposure-offset names camera {name}, which is not one of the rig's cameras "
                f"({', '.join(cameras)})"
            )
        if name in declared:
            raise UsageError(
                f"camera {name}'s exposure offset is both declared and to be estimated: give one"
            )
    if len(set(names)) < len(names):
        raise UsageError("--estimate-exposure-offset names a camera twice")


def _with_estimated_offsets(
    timed: rig_video.VideoRigCapture,
    cameras: Sequence[str],
    members: Sequence[MemberIntrinsics],
    spec: BoardSpec,
    model: str,
    names: Sequence[str],
) -> rig_video.VideoRigCapture:
    """The capture with each named camera's exposure offset estimated from the data and applied: the rig
    solved (members fixed) with that camera's corners interpolated at offsets ESTIMATE_STEP_MS apart, from 0
    each way while the residual falls (and two steps on), up to half its frame interval; the minimum of the
    mean squared residual over the views every offset keeps, and its sd over a bootstrap of the rig frames
    (core.extrinsics.rig_frame_shift.offset_minimum). NumericalError (exit 2) when there is no minimum
    inside that range with a stated sd: a board standing still or moving steadily cannot show the offset."""
    offsets_s = dict(timed.exposure_offsets_s or {})
    sd_s: dict[str, float] = {}
    solve_model = model if model != "auto" else DEFAULT_MODEL
    for name in names:
        assert timed.frame_times is not None
        times_s = {i: t for i, t in enumerate(timed.frame_times[name]) if t is not None}
        limit_ms = 0.5 * median_interval_s(times_s) * 1e3

        def squared(ms: float, name: str = name) -> dict[tuple[str, int], float]:
            cap = rig_video.with_exposure_offsets(timed, {**offsets_s, name: ms / 1e3})
            views = rig_views(cameras, cap.match, {n: rig_video.rig_outcomes(cap, n) for n in cameras}, spec)
            sol = solve_rig(views, members, model=solve_model)
            ne = rig_covariance(sol.views, list(sol.members), sol.cam_poses, sol.board_poses, False)
            return {
                (sol.views.frames[f], c): float(np.mean(np.sum(r**2, axis=1)))
                for (f, c), r in ne.normal_equations.residuals_px.items()
            }

        scan = {0.0: squared(0.0)}
        for step in (-ESTIMATE_STEP_MS, ESTIMATE_STEP_MS):
            ms, rising = step, 0
            while abs(ms) < limit_ms and rising < 2:
                scan[ms] = squared(ms)
                rising = rising + 1 if _mean(scan[ms]) >= _mean(scan[ms - step]) else 0
                ms += step
        offsets = sorted(scan)
        found = offset_minimum(offsets, [scan[ms] for ms in offsets])
        if found is None:
            raise NumericalError(
                f"camera {name}'s exposure offset cannot be estimated: the rig's residual has no clear "
                f"minimum within {offsets[0]:+.0f}..{offsets[-1]:+.0f} ms that the rig frames agree on",
                hint=f"a board standing still or moving steadily cannot show it: declare it "
                f"(--exposure-offset {name}=MS) or capture a board that changes direction",
            )
        offsets_s[name], sd_s[name] = found[0] / 1e3, found[1] / 1e3
    estimated = rig_video.with_exposure_offsets(timed, offsets_s)
    return replace(estimated, estimated_sd_s=sd_s)


def _mean(squared: Mapping[tuple[str, int], float]) -> float:
    return float(np.mean(list(squared.values()))) if squared else float("nan")


def _auto_rig_model(fits: Mapping[str, MemberFit], refine_intrinsics: bool) -> str:
    """The rig solve's model once auto chose each member's: it only sets the flags of a jointly refined
    two-camera solve, so members that chose differently cannot be refined together (UsageError)."""
    chosen = {name: fit.model for name, fit in fits.items()}
    if refine_intrinsics and len(set(chosen.values())) > 1:
        listed = ", ".join(f"{name}: {m}" for name, m in chosen.items())
        raise UsageError(
            f"--model auto chose different lens models for the cameras ({listed}); their intrinsics "
            "cannot be refined jointly",
            "leave out --refine-intrinsics, or give one --model for all",
        )
    return next(iter(chosen.values()), DEFAULT_MODEL)


def judged_solve(
    run: RigFolderRun,
    model: str = DEFAULT_MODEL,
    refine_intrinsics: bool = False,
    limits: LintThresholds | None = None,
) -> RigFolderRun:
    """``run`` solved (extrinsics, held-out numbers, loops) and judged (module docstring). A run without
    ``member_verdicts`` (corners without photos) holds its members to ``model-misfit`` alone."""
    views, members, fits = run.views, list(run.members), run.fits or {}
    limits = limits or LintThresholds()
    if run.member_verdicts is not None:
        misfit = [f for found in run.member_verdicts.values() for f in found]
        bad_lens = {
            name
            for name, found in run.member_verdicts.items()
            if any(f.rule == "member:model-misfit" for f in found)
        }
    else:
        lens = {
            name: adopt(model_fit.check_model_misfit(fit.fit_rms_px, fit.detector_rms_px, fit.model))
            for name, fit in fits.items()
        }
        misfit = [member_finding(name, f) for name, found in lens.items() for f in found]
        bad_lens = {name for name, found in lens.items() if found}
    try:
        solution = solve_rig(views, members, refine_intrinsics, model)
        holdout = validate_rig_holdout(views, members, refine_intrinsics, model)
        loops = loop_closures(views, members, model) if len(run.cameras) >= 3 else ()
    except InconsistentDataError as exc:
        rigid = Finding(rule="rig-rigid", severity="error", message=exc.message, fix=exc.hint)
        return replace(run, findings=(rigid, *misfit))
    rows = {m.name: m.image_size[1] for m in members}
    pairs = rig_pairs(solution, holdout)
    findings = solved_rig_findings(pairs, rig_loops(loops), rows, run.designs, limits, bad_lens)
    same = [
        Finding(
            rule="rig-identity",
            severity="error",
            message=f.message,
            fix="give each camera its own photos (was the same folder given twice?)",
        )
        for f in identity.zero_baselines(identity.pair_translations(solution))
    ]
    scale = square_size_findings(solution, run.square_mm)
    return replace(
        run, solution=solution, holdout=holdout, loops=loops, findings=(*same, *findings, *misfit, *scale)
    )


def square_size_findings(solution: RigSolution, square_mm: float | None) -> list[Finding]:
    """A warning (``square-size``) when the square size given is outside what boards are printed with
    (``PLAUSIBLE_SQUARE_MM``): every length the solve reports scales with it, so a 2.5 typed for 25 passes a
    75 mm rig as 7.5 mm, seen from a tenth of its real working distance, without any residual showing it.
    ``--square-mm 1`` is the unit square of a board whose size is unknown (every length in squares): no
    warning."""
    lo, hi = PLAUSIBLE_SQUARE_MM
    if square_mm is None or lo <= square_mm <= hi or square_mm == 1.0:  # 1: lengths in squares, as asked
        return []
    baselines = [float(np.linalg.norm(p[3:])) * 1e3 for p in solution.cam_poses[1:]]
    distance_mm = float(np.median(np.linalg.norm(solution.board_poses[:, 3:], axis=1))) * 1e3
    return [
        Finding(
            rule="square-size",
            severity="warning",
            message=f"--square-mm {square_mm:g} is outside the {lo:g}-{hi:g} mm that boards are printed "
            f"with: it makes the baseline {min(baselines):.1f} mm and the board {distance_mm:.0f} mm from "
            "the root camera (every length scales with the square size)",
            fix="measure a square with calipers and give --square-mm in millimetres (a slipped decimal point "
            "scales every length of the rig tenfold)",
        )
    ]


def rig_pairs(solution: RigSolution, holdout: RigHoldout | None) -> list[RigPair]:
    """``pair_summary`` as the stored rig's pair records."""
    return [RigPair(**{k: v for k, v in p.items() if k != "pair"}) for p in pair_summary(solution, holdout)]


def rig_loops(loops: Sequence[LoopClosure]) -> list[RigLoop]:
    """Loop closures as the stored rig's loop records."""
    return [
        RigLoop(
            cycle=list(lc.cycle),
            rotation_deg=lc.rotation_deg,
            translation_mm=lc.translation_mm,
            sigma_rotation_deg=lc.sigma_rotation_deg,
            sigma_translation_mm=lc.sigma_translation_mm,
            mahalanobis=lc.mahalanobis,
        )
        for lc in loops
    ]


def pair_summary(solution: RigSolution, holdout: RigHoldout | None) -> list[dict[str, object]]:
    """Per pair (a < b): baseline mm and rotation deg with one-sigma, and the held-out numbers."""
    rows = []
    names = solution.views.cameras
    held = {(p.a, p.b): p for p in (holdout.pairs if holdout else ())}
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            T = solution.T_a_b(b, a)
            cov = solution.pair_covariance(b, a)
            row: dict[str, object] = {
                "pair": f"{names[a]}-{names[b]}",
                "a": names[a],
                "b": names[b],
                "baseline_mm": float(np.linalg.norm(T[:3, 3]) * 1e3),
                "sigma_baseline_mm": sigma_translation_mm(cov, T[:3, 3]),
                "rotation_deg": rotation_angle_deg(T[:3, :3]),
                "sigma_rotation_deg": sigma_rotation_deg(cov),
                "shared_views": solution.views.shared_view_counts()[(a, b)],
            }
            if (a, b) in held:
                p = held[(a, b)]
                row.update(
                    {
                        "epipolar_rms_px": p.epipolar_rms_px,
                        "epipolar_max_px": p.epipolar_max_px,
                        "rectified_rms_px": p.rectified_rms_px,
                        "rectified_max_px": p.rectified_max_px,
                    }
                )
            rows.append(row)
    return rows


def _fit_json(fit: MemberFit | None) -> dict[str, object]:
    if fit is None:  # intrinsics given, not self-calibrated
        return {}
    return {"model": fit.model, "fit_rms_px": fit.fit_rms_px, "detector_rms_px": fit.detector_rms_px}


def run_json(run: RigFolderRun) -> dict[str, object]:
    """The run as plain JSON types (``--json``)."""
    g = run.gate
    out: dict[str, object] = {
        "cameras": list(run.cameras),
        "frames": len(run.match.frames),
        "unmatched": [
            {"camera": u.camera, "file": Path(u.path).name, "reason": u.reason} for u in run.match.unmatched
        ],
        "images": {
            n: {
                s: sum(1 for o in run.outcomes[n] if o.status == s)
                for s in {o.status for o in run.outcomes[n]}
            }
            for n in run.cameras
        },
        "shared_views": {
            f"{run.cameras[a]}-{run.cameras[b]}": n for (a, b), n in run.views.shared_view_counts().items()
        },
        "gate": {
            "gate": g.gate,
            "passed": g.passed,
            "value": g.value,
            "threshold": g.threshold,
            "message": g.message,
            "hint": g.hint,
        },
        "members": [
            {
                "name": m.name,
                "image_size": list(m.image_size),
                "K": np.asarray(m.camera_matrix).tolist(),
                "dist": np.asarray(m.dist_coeffs).tolist(),
                **_fit_json((run.fits or {}).get(m.name)),
            }
            for m in run.members
        ],
    }
    if run.timing is not None:
        out["timing"] = dict(run.timing)
    if run.refused:
        out["refused"] = [f.model_dump(mode="json", exclude_none=True) for f in run.refused]
    if run.gate.passed or run.findings:  # a failed gate leaves no verdict to give, but the gauge judges
        out["verdict"] = "pass" if run.passed else "fail"
        out["lint"] = [f.model_dump(mode="json", exclude_none=True) for f in run.findings]
    sol = run.solution
    if sol is None:
        return out
    out["solver"] = sol.solver
    out["root"] = sol.tree.root
    out["tree"] = [
        {
            "parent": e.parent,
            "child": e.child,
            "T_parent_child": e.T_parent_child.tolist(),
            "translation_mm": e.translation_mm,
            "sigma_translation_mm": e.sigma_translation_mm,
            "rotation_deg": e.rotation_deg,
            "sigma_rotation_deg": e.sigma_rotation_deg,
        }
        for e in sol.tree.edges
    ]
    out["fit_rms_px"] = dict(zip(run.cameras, sol.rms_px, strict=True))
    if run.holdout is not None:
        out["held_out"] = {
            "folds": run.holdout.n_folds,
            "rms_px": dict(zip(run.cameras, run.holdout.camera_rms_px, strict=True)),
        }
    out["pairs"] = pair_summary(sol, run.holdout)
    out["loops"] = [
        {
            "cycle": list(lc.cycle),
            "rotation_deg": lc.rotation_deg,
            "translation_mm": lc.translation_mm,
            "sigma_rotation_deg": lc.sigma_rotation_deg,
            "sigma_translation_mm": lc.sigma_translation_mm,
            "mahalanobis": lc.mahalanobis,
        }
        for lc in run.loops
    ]
    return out
