"""``calibctl check SERIAL[@N] --source SRC``: re-test a stored calibration on fresh board views.

Detection is capture's (``core.capture.image_outcomes``: the same detector, near-duplicate and size rules),
the maths is ``core.check.recheck`` (poses by solvePnP with the stored model, residuals against the
calibration's own held-out RMS per region, focal/principal-point pulls). The calibration is never
re-solved or changed; the check is stored as an event in the serial's history (``Store.add_check``).

With ``--reference-distance D+-S`` (the board held by a fixture at a surveyed distance from the
camera) the recovered distance is compared with it: a ratio outside 0.99-1.01 fails, because a wrong
metric scale (seed chapter 0: a 23 mm board that is really 25 mm) leaves no residual to see.
"""

from __future__ import annotations

import re
import secrets
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.check import CheckEvent, DistanceCheck, RegionCheck, ShiftCheck
from calibctl.artifacts.common import utc_now
from calibctl.config import Settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import image_outcomes as outcomes_core
from calibctl.core.check.recheck import DEFAULT_ALPHA, MIN_CHECK_VIEWS, RecheckResult, Reference, recheck
from calibctl.core.intrinsics.solve import residual_rms_px
from calibctl.core.intrinsics.validation import N_OCTANTS, N_RINGS, refit_pose_residuals
from calibctl.errors import InputError, UsageError
from calibctl.workflows.board.boards import board_spec
from calibctl.workflows.camera import capture_sources as sources
from calibctl.workflows.camera.distance_gauge import (
    ReferenceDistance,
    board_distances_m,
    detect_fixture_views,
    distance_reason,
    judge_distance,
)
from calibctl.workflows.store_admin.records import open_store, parse_artifact_ref

_RING_EDGE = re.compile(r"r (?P<lo>[0-9.]+)-(?P<hi>[0-9.]+) px")


@dataclass(frozen=True)
class CheckRequest:
    ref: str
    source: str
    reference_distance: ReferenceDistance | None = None


def reference_of(art: CalibrationArtifact) -> Reference:
    """The calibration's held-out numbers as ``core.check.recheck`` reads them (ring edges from the ring
    labels)."""
    held = art.held_out
    if held.rms_px is None or held.k_folds == 0:
        raise UsageError(
            f"{art.ref} has no held-out RMS to compare with (too few views when it was solved)",
            "check a version solved from enough views, or recalibrate",
        )
    edges = [_RING_EDGE.search(r.label) for r in held.by_radius[: N_RINGS - 1]]
    ring_edges = (
        np.array([float(m.group("hi")) for m in edges if m is not None])
        if len(held.by_radius) == N_RINGS and all(edges)
        else None
    )

    def column(rings: list, n: int) -> tuple[np.ndarray, np.ndarray]:
        if len(rings) != n:
            return np.full(n, np.nan), np.zeros(n, np.int64)
        return (
            np.array([np.nan if r.held_out_rms_px is None else r.held_out_rms_px for r in rings]),
            np.array([r.count for r in rings], np.int64),
        )

    ring_rms, ring_counts = column(held.by_radius, N_RINGS)
    oct_rms, oct_counts = column(held.by_octant, N_OCTANTS)
    n_views = sum(1 for v in art.views if not v.dropped) or len(art.views)
    n_corners = int(ring_counts.sum()) or art.board.cols * art.board.rows * n_views  # artifacts without rings
    return Reference(held.rms_px, n_corners, n_views, ring_edges, ring_rms, ring_counts, oct_rms, oct_counts)


def stored_covariance(art: CalibrationArtifact) -> np.ndarray | None:
    """(3, 3) covariance of the stored (focal scale, cx px, cy px) from the artifact's full covariance, or
    None.

    focal scale = the mean of dfx/fx and dfy/fy (fx = aspect * fy when the solve tied them: dfy/fy).
    A parameter the solve held fixed contributes nothing.
    """
    cov = art.stdev.covariance
    if cov is None:
        return None
    names = list(cov.parameters)
    G = np.zeros((3, len(names)))
    focal = [
        (name, value)
        for name, value in (("fx", art.camera_matrix[0][0]), ("fy", art.camera_matrix[1][1]))
        if name in names
    ]
    for name, value in focal:
        G[0, names.index(name)] = 1.0 / (value * len(focal))
    for row, name in ((1, "cx"), (2, "cy")):
        if name in names:
            G[row, names.index(name)] = 1.0
    return G @ np.asarray(cov.matrix, np.float64) @ G.T


def stored_sigma(art: CalibrationArtifact) -> dict[str, float]:
    sigma = art.stdev.sigma
    out: dict[str, float] = {name: sigma[name] for name in ("cx", "cy") if name in sigma}
    if "fx" in sigma:
        out["focal"] = sigma["fx"] / art.fx
    return out


def _event(
    art: CalibrationArtifact,
    settings: Settings,
    source: sources.SourceSpec,
    n_images: int,
    views: list[outcomes_core.ImageOutcome],
    result: RecheckResult,
    distance: DistanceCheck | None,
) -> CheckEvent:
    reasons = [
        f"{r.region}: RMS {r.check_rms_px:.3f} px is {r.ratio:.2f}x the calibration's held-out "
        f"{r.reference_rms_px:.3f} px (limit {r.limit:.2f}x)"
        for r in result.failed_regions
    ]
    reasons += [
        f"{p.name} moved {_shift_text(p.name, p.shift)} ({p.z:+.1f} sigma, limit {p.z_limit:.1f})"
        for p in result.failed_shifts
    ]
    if distance is not None and not distance.passed:
        reasons.append(distance_reason(distance))
    regions = [
        RegionCheck(
            region=r.region,
            check_rms_px=_finite(r.check_rms_px),
            reference_rms_px=_finite(r.reference_rms_px),
            ratio=r.ratio if r.tested else None,
            limit=r.limit,
            corners=r.n_corners,
            tested=r.tested,
            passed=r.passed,
        )
        for r in result.regions
    ]
    shifts = [
        ShiftCheck(parameter=p.name, shift=p.shift, sigma=p.sigma, z_limit=p.z_limit, passed=p.passed)
        for p in result.shifts
    ]
    return _stamped(
        art,
        settings,
        source,
        n_images,
        views,
        view_rms_px=[float(x) for x in result.view_rms_px],
        regions=regions,
        shifts=shifts,
        distance=distance,
        alpha=result.alpha,
        passed=result.passed and (distance is None or distance.passed),
        reasons=reasons,
    )


def _stamped(
    art: CalibrationArtifact,
    settings: Settings,
    source: sources.SourceSpec,
    n_images: int,
    views: list[outcomes_core.ImageOutcome],
    **verdict: Any,
) -> CheckEvent:
    """A check event of ``art`` on ``views``: id, what, where, when and who, with the ``verdict`` fields."""
    return CheckEvent(
        check_id=secrets.token_hex(6),
        serial=art.serial,
        version=art.version,
        calibration_sha256=art.content_sha256,
        source=source.recorded,
        station=settings.station,
        operator=settings.operator,
        at=utc_now(),
        image_size=art.image_size,
        images=n_images,
        views=[v.name for v in views],
        **verdict,
    )


ONE_POSE_PX = 3.0  # a fixture holds the board still: its pictures' corners agree to a few pixels at most


def one_pose(views: list[outcomes_core.ImageOutcome]) -> None:
    """A fixture check reads one pose of the board: pictures whose shared corners lie more than ONE_POSE_PX
    apart (median) show several poses (InputError, exit 2, naming the two pictures)."""
    first = views[0]
    ids, px = first.corner_ids, first.corners_px
    assert ids is not None and px is not None  # accepted views carry corners (detect_fixture_views)
    where = {int(i): np.asarray(p) for i, p in zip(ids, px, strict=True)}
    for v in views[1:]:
        moved = [
            float(np.linalg.norm(np.asarray(p) - where[int(i)]))
            for i, p in zip(v.corner_ids, v.corners_px, strict=True)  # type: ignore[arg-type]
            if int(i) in where
        ]
        shift = float(np.median(moved)) if moved else float("inf")
        if shift > ONE_POSE_PX:
            raise InputError(
                f"the fixture pictures show the board in several poses: {v.name} is {shift:.1f} px from "
                f"{first.name} (a fixture holds one pose; at most {ONE_POSE_PX:g} px); nothing was stored",
                "give only the pictures taken with the board in the fixture; for the statistical re-test "
                f"take at least {MIN_CHECK_VIEWS} pictures, tilted, across the image",
            )


def _fixture_event(
    art: CalibrationArtifact,
    settings: Settings,
    spec: BoardSpec,
    source: sources.SourceSpec,
    n_images: int,
    views: list[outcomes_core.ImageOutcome],
    reference: ReferenceDistance,
) -> CheckEvent:
    """The metric gauge (seed chapter 0) from a few pictures of the board in its fixture: the board distance
    through the stored lens against the surveyed one. The statistical re-test is not run (it needs
    MIN_CHECK_VIEWS views of many poses) and the event says so."""
    one_pose(views)
    K, dist = np.array(art.camera_matrix), np.array(art.dist_coeffs)
    recovered = board_distances_m(spec, views, K, dist, art.model.name)
    distance = judge_distance(reference, recovered, [v.name for v in views])
    obj = spec.object_points()
    view_rms = [
        residual_rms_px(
            refit_pose_residuals(
                obj[np.asarray(v.corner_ids)], np.asarray(v.corners_px), K, dist, art.model.name
            )
        )
        for v in views
    ]
    return _stamped(
        art,
        settings,
        source,
        n_images,
        views,
        view_rms_px=[float(x) for x in view_rms],
        regions=[],
        shifts=[],
        distance=distance,
        alpha=DEFAULT_ALPHA,
        passed=distance.passed,
        reasons=[] if distance.passed else [distance_reason(distance)],
        not_judged=[
            f"the statistical re-test (residuals per region, focal and principal-point pulls): {len(views)} "
            f"picture(s) of one pose; it needs {MIN_CHECK_VIEWS} views, tilted, across the image"
        ],
    )


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _shift_text(name: str, shift: float) -> str:
    return f"{shift * 100:+.2f} %" if name == "focal" else f"{shift:+.2f} px"


def check(settings: Settings, request: CheckRequest) -> CheckEvent:
    """Re-test the calibration ``request.ref`` names on fresh images and store the event (see module
    docstring).

    Raises CalibctlError (exit 2) when the check cannot run: unknown serial/version, a source that is
    not a set of images, images of another size, no board found, an unusable reference distance.
    """
    serial, version = parse_artifact_ref(request.ref)
    source = sources.resolve_source(request.source)
    with open_store(settings, write=True) as store:  # write: the check event is signed with the station key
        art = store.get_artifact(serial, version)
        reference = reference_of(art)
        spec = board_spec(art.board)
        if source.kind not in sources.IMAGE_SETS:
            raise UsageError(
                f"check reads a folder, glob or list of images, not a {source.kind}",
                "save a few board pictures from the camera and check those",
            )
        views, n_images = detect_fixture_views(
            spec, art.board.ref, source, art.image_size, art.ref, settings.jobs
        )
        if len(views) < MIN_CHECK_VIEWS and request.reference_distance is not None:
            event = _fixture_event(art, settings, spec, source, n_images, views, request.reference_distance)
            return store.add_check(event)
        if len(views) < MIN_CHECK_VIEWS:  # refused before anything is stored: a FAIL here would be noise
            raise InputError(
                f"cannot judge {art.ref} from {len(views)} board view(s) in {n_images} image(s): the "
                f"check's statistics need at least {MIN_CHECK_VIEWS}; nothing was stored",
                f"take {MIN_CHECK_VIEWS - len(views)} more pictures of the board (tilted, across the "
                "image) and check again; or, with the board in a surveyed fixture, give --reference-distance "
                "D+-S to judge the metric gauge from these",
            )
        obj = spec.object_points()
        ids = [np.asarray(v.corner_ids) for v in views]
        result = recheck(
            [obj[i] for i in ids],
            [np.asarray(v.corners_px) for v in views],
            np.array(art.camera_matrix),
            np.array(art.dist_coeffs),
            art.image_size,
            reference,
            stored_sigma(art),
            model=art.model.name,
            stored_covariance=stored_covariance(art),
        )
        distance = None
        if request.reference_distance is not None:
            distance = judge_distance(
                request.reference_distance, result.board_distance_m, [v.name for v in views]
            )
        event = _event(art, settings, source, n_images, views, result, distance)
        return store.add_check(event)
