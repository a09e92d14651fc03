"""The decisive capture gate: how well the calibration predicts the region the robot uses.

Tilt directions and covered cells are proxies for what matters: whether the calibrated lens predicts where
a ray lands. This gate solves the session (the lens model it will be solved with; without one, the better
fit of k1k2 and fisheye), propagates the intrinsic covariance calibctl reports (the Jacobian one, widened
by the view-level factor where the views scatter more than their corners explain) to pixels (core.intrinsics.
report_maps, as the report draws it and as mrcal's show-projection-uncertainty does in its simplest form) and
judges the worst one-sigma over a region:

- ``image``: the whole image (the default for a pinhole or full-frame lens);
- ``circle``: the image circle of a circular fisheye (the default when one is known);
- ``U0,V0,U1,V1``: a station-declared box, pixels (the part of the image the robot uses).

Grid: GRID_STEP_PX-spaced cell centres (at least 16 x 12), so a corner region is judged by the cells in it.
Each intrinsic perturbation's pixel shifts are taken less the camera rotation that best explains them over
the region (report_maps ``rotation_fit``; mrcal compensates the same way, with the full frame transform):
a principal point shift that the extrinsics absorb does not move one ray relative to another. Without it
the map is an upper bound dominated by sigma(cx, cy) at the centre and by extrapolation at the corners. Where
the region fails, the message names the 3 x 3 cells (capture's words: "bottom-left corner") whose worst sigma
is over.

With this gate in the session, tilt and coverage are guidance (``advisory``): the session's verdict is
observability, views, one camera and this gate. A session that cannot be solved at all fails this gate
with the solver's reason, and the proxies' hints say what to capture.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from calibctl.core.capture.gates import CELL_NAMES, COVERAGE_GRID
from calibctl.core.gate import GateResult
from calibctl.core.intrinsics.board_warp import BoardWarp, fit_board_warp
from calibctl.core.intrinsics.camera_change import changed_hint, judge_change
from calibctl.core.intrinsics.covariance import IntrinsicCovariance
from calibctl.core.intrinsics.model_fit import WIDE_FIELD_DEG, diagonal_field_deg
from calibctl.core.intrinsics.report_maps import projection_uncertainty
from calibctl.core.intrinsics.solve import IntrinsicsSolution, solve_intrinsics
from calibctl.errors import NumericalError

GRID_STEP_PX = 20.0
MIN_GRID = (16, 12)
PROJECTION_SIGMA_MAX_PX = 5.0  # default station threshold; measured table in docs/verdicts.md
ADVISORY_GATES = ("tilt", "coverage")  # guidance once the projection gate decides
UNKNOWN_LENS_MODELS = ("k1k2", "fisheye")
FISHEYE_GAIN = 0.10  # model_select.MIN_FIT_IMPROVEMENT
CIRCLE_VERTICES = 72  # a circle region as a polygon (Region.vertices_px)
WORST_VIEWS_NAMED = 3  # views a scatter hint names, worst first
UNKNOWN_SIGMA_PX = 1e6  # a grid pixel the model cannot unproject (value stays finite: artifacts refuse inf)


@dataclass(frozen=True)
class Region:
    """Where the robot looks. kind: image | circle | box; box_px (u0, v0, u1, v1); circle_px (cx, cy, r)."""

    kind: str
    box_px: tuple[float, float, float, float] | None = None
    circle_px: tuple[float, float, float] | None = None

    def describe(self) -> str:
        if self.kind == "circle" and self.circle_px is not None:
            cx, cy, r = self.circle_px
            return f"the image circle ({cx:.1f}, {cy:.1f}) r {r:.1f} px"
        if self.kind == "box" and self.box_px is not None:
            return "the box ({:g}, {:g})-({:g}, {:g}) px".format(*self.box_px)
        return "the whole image"

    def vertices_px(self, image_size: tuple[int, int]) -> np.ndarray:
        """(K, 2) px points whose farthest one from any principal point bounds the region (lint's fold-over
        reads the farthest): the box's or the image's corners, or the circle sampled (CIRCLE_VERTICES, grown
        so the polygon contains the circle) and clipped to the image."""
        w, h = image_size
        if self.kind == "circle" and self.circle_px is not None:
            cx, cy, r = self.circle_px
            a = np.linspace(0.0, 2 * np.pi, CIRCLE_VERTICES, endpoint=False)
            r_out = r / math.cos(math.pi / CIRCLE_VERTICES)
            return np.column_stack(
                [
                    np.clip(cx + r_out * np.cos(a), -0.5, w - 0.5),
                    np.clip(cy + r_out * np.sin(a), -0.5, h - 0.5),
                ]
            )
        u0, v0, u1, v1 = (
            self.box_px if self.kind == "box" and self.box_px is not None else (-0.5, -0.5, w - 0.5, h - 0.5)
        )
        return np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], np.float64)

    def mask(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(R, C) bool: the grid points (u (C,), v (R,) px) inside the region."""
        uu, vv = np.meshgrid(u, v)
        if self.kind == "circle" and self.circle_px is not None:
            cx, cy, r = self.circle_px
            return np.hypot(uu - cx, vv - cy) <= r
        if self.kind == "box" and self.box_px is not None:
            u0, v0, u1, v1 = self.box_px
            return (uu >= u0) & (uu <= u1) & (vv >= v0) & (vv <= v1)
        return np.ones(uu.shape, dtype=bool)


def parse_region(
    text: str, image_size: tuple[int, int], circle_px: tuple[float, float, float] | None
) -> Region:
    """A station's region text -> Region. ``auto``: the circle when one is known, else the image.

    Raises:
        ValueError: unknown text, a box that is not four finite numbers u0 < u1, v0 < v1 inside the
            image, or ``circle`` without a known image circle (the message says which).
    """
    w, h = image_size
    word = text.strip().lower()
    if word == "auto":
        return Region("image") if circle_px is None else Region("circle", circle_px=circle_px)
    if word == "image":
        return Region("image")
    if word == "circle":
        if circle_px is None:
            raise ValueError(
                "projection region 'circle' needs an image circle, and none is known for this session"
            )
        return Region("circle", circle_px=circle_px)
    try:
        box = tuple(float(x) for x in word.split(","))
    except ValueError:
        raise ValueError(f"projection region '{text}' is not auto, image, circle or U0,V0,U1,V1") from None
    if len(box) != 4 or not all(math.isfinite(x) for x in box):
        raise ValueError(f"projection region '{text}' is not four finite numbers U0,V0,U1,V1")
    u0, v0, u1, v1 = box
    if not (0 <= u0 < u1 <= w and 0 <= v0 < v1 <= h):
        raise ValueError(
            f"projection region ({u0:g}, {v0:g})-({u1:g}, {v1:g}) px is not a box inside the {w}x{h} image"
        )
    return Region("box", box_px=(u0, v0, u1, v1))


def check_threshold(threshold_px: float) -> float:
    """The station threshold, px (ValueError unless finite and positive)."""
    if not (math.isfinite(threshold_px) and threshold_px > 0):
        raise ValueError(f"projection threshold {threshold_px} px must be a finite number above 0")
    return float(threshold_px)


def solve_for_gate(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    model: str | None,
) -> IntrinsicsSolution:
    """The session solved with ``model`` (with uncertainty). None (a capture that does not know the lens):
    k1k2, or fisheye when it fits at least FISHEYE_GAIN better (--model auto's 10 % rule, core.intrinsics.
    model_select): a fisheye fitted to a pinhole lens fits its corners as well and extrapolates to the image
    corners at thousands of px (opencv-left-right left: 0.195 against 0.196 px, sigma 61805 px there).

    Raises:
        NumericalError: no model could be solved (the last one's reason).
    """
    fits, last = {}, None
    for name in (model,) if model is not None else UNKNOWN_LENS_MODELS:
        try:
            fits[name] = solve_intrinsics(list(object_points), list(image_points), image_size, name)
        except NumericalError as exc:
            last = exc
    if not fits:
        assert last is not None
        raise last
    if model is not None:
        return fits[model]
    pinhole, fisheye = fits.get("k1k2"), fits.get("fisheye")
    if pinhole is None or (fisheye is not None and fisheye.rms_px <= (1.0 - FISHEYE_GAIN) * pinhole.rms_px):
        return fisheye if fisheye is not None else pinhole  # type: ignore[return-value]
    return pinhole


def projection_gate(
    solution: IntrinsicsSolution | NumericalError,
    image_size: tuple[int, int],
    region: Region,
    threshold_px: float,
) -> GateResult:
    """The gate (module docstring) from a solve with uncertainty, or the error that stopped it (value 0 then:
    nothing was measured; the reason says so)."""
    limit = check_threshold(threshold_px)
    where = region.describe()
    if isinstance(solution, NumericalError):
        return GateResult(
            "projection",
            False,
            0.0,
            limit,
            f"the session cannot be solved: {solution.message}",
            "projection.unsolvable",
            solution.hint or "capture views tilted 20-40 deg in at least three directions covering the image",
            {"region": where},
        )
    cov = solution.covariance
    if cov is None or cov.covariance is None or solution.sigma_refused_reason:
        reason = solution.sigma_refused_reason or "no covariance"
        return GateResult(
            "projection",
            False,
            0.0,
            limit,
            f"the {solution.model} solve has no uncertainty to propagate: {reason}",
            "projection.no_covariance",
            "capture views tilted 20-40 deg in at least three directions",
            {"region": where, "model": solution.model},
        )
    u_px, v_px, sigma, beyond = _sigma_grid(solution, cov, image_size, region)
    inside = sigma >= 0
    worst = float(sigma.max()) if inside.any() else 0.0
    detail: dict[str, float | int | str | list[str]] = {"region": where, "model": solution.model}
    widened = f", view-level x {cov.view_factor:.2f}" if cov.inflated and cov.view_factor else ""
    if widened:
        detail["view_factor"] = round(float(cov.view_factor or 0.0), 3)
    if beyond.any():
        detail["not_judged_beyond_88_deg"] = int(beyond.sum())
    over = _cells_over(sigma, u_px, v_px, image_size, limit)
    message = (
        f"worst projection one-sigma over {where}: {worst:.3g} px ({solution.model} lens{widened}; "
        f"limit {limit:g} px)"
    )
    if worst <= limit:
        return GateResult("projection", True, worst, limit, message, detail=detail)
    detail["uncertain_cells"] = over
    return GateResult(
        "projection",
        False,
        worst,
        limit,
        f"{message}; uncertain at the {', '.join(over)}",
        "projection.uncertain",
        f"capture views with the board in the {', '.join(over)} (tilted 20-40 deg), where the "
        "calibration does not yet predict the lens",
        detail,
    )


def _sigma_grid(
    solution: IntrinsicsSolution, cov: IntrinsicCovariance, image_size: tuple[int, int], region: Region
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """u (C,), v (R,) px, the judged one-sigma (R, C) px (-1 outside the region or not judged) and the
    (R, C) mask of a fisheye's rays past 88 deg off-axis (no projection to judge there)."""
    w, h = image_size
    grid = (max(MIN_GRID[0], round(w / GRID_STEP_PX)), max(MIN_GRID[1], round(h / GRID_STEP_PX)))
    u = (np.arange(grid[0]) + 0.5) * w / grid[0] - 0.5
    v = (np.arange(grid[1]) + 0.5) * h / grid[1] - 0.5
    assert cov.covariance is not None
    # the covariance calibctl reports and stores: the Jacobian one, widened by the view-level factor where
    # the views scatter more than their corners explain (core/intrinsics/covariance.py)
    umap = projection_uncertainty(
        solution.camera_matrix,
        solution.dist_coeffs,
        cov.covariance,
        cov.names,
        solution.aspect_ratio,
        image_size,
        grid,
        fisheye=solution.model == "fisheye",
        rotation_fit=region.mask(u, v),
    )
    inside = region.mask(umap.u_px, umap.v_px)
    beyond = inside & np.isnan(umap.sigma_px)
    inside &= ~beyond
    sigma = np.where(inside & np.isfinite(umap.sigma_px), umap.sigma_px, -1.0)
    sigma[inside & np.isinf(umap.sigma_px)] = UNKNOWN_SIGMA_PX
    return umap.u_px, umap.v_px, sigma, beyond


def worst_where_seen(
    solution: IntrinsicsSolution,
    cov: IntrinsicCovariance,
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    region: Region,
) -> float:
    """The worst judged one-sigma over the grid cells that hold a detected corner: where the board was seen,
    so more views of other places cannot be what it lacks."""
    u, v, sigma, _ = _sigma_grid(solution, cov, image_size, region)
    px = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in image_points])
    ci = np.clip(np.rint((px[:, 0] + 0.5) * len(u) / image_size[0] - 0.5).astype(int), 0, len(u) - 1)
    ri = np.clip(np.rint((px[:, 1] + 0.5) * len(v) / image_size[1] - 0.5).astype(int), 0, len(v) - 1)
    return float(sigma[ri, ci].max())


def cause_first(
    gate: GateResult,
    solution: IntrinsicsSolution | NumericalError,
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    region: Region,
    threshold_px: float,
) -> GateResult:
    """A failed gate whose uncertainty a cause other than the views explains, with that cause and its fix
    first (the views' hint after it): a pinhole model on a wide lens that the fisheye model fits at least
    FISHEYE_GAIN better (``projection.lens_model``; judged first: a misfit model also makes the two halves of
    a session disagree), else a camera that changed during the session (core.intrinsics.camera_change,
    ``projection.camera_changed``), else, when the view-level factor widened the sigma, a board that is not
    flat (core.intrinsics.board_warp, ``projection.board_not_flat``) or, when no bow explains the views'
    scatter, a board that moved or flexed between views (``projection.views_scatter``). Any other gate is
    returned as it is."""
    if gate.passed or gate.reason != "projection.uncertain" or isinstance(solution, NumericalError):
        return gate
    lens = _lens_model_cause(gate, solution, object_points, image_points, image_size, region, threshold_px)
    if lens is not None:
        return lens
    cov = solution.covariance
    per_view = cov is not None and cov.inflated  # the views scatter more than their corners explain
    # a bowed board before a changed camera: a bow can read as a step between the views (a render bowed
    # 1 mm did), a step is never absorbed by a bow (renders with focal and centre steps: factor unchanged)
    warp = fit_board_warp(solution, object_points, image_points) if per_view else None
    if warp is not None and warp.explains_views:
        return _board_cause(gate, warp, image_size, region, threshold_px)
    change = judge_change(solution, object_points, image_points, image_size)
    if change is not None and change.changed:
        return replace(
            gate,
            message=f"{gate.message}; the views before and after view {change.split} disagree (chi2 "
            f"{change.chi2:.1f}, limit {change.limit:g}): the uncertainty is a blend of two cameras",
            reason="projection.camera_changed",
            hint=f"{changed_hint(change.focal_step, change.centre_step_px)}; then, if it is still uncertain: "
            f"{gate.hint}",
        )
    if not per_view or cov is None:
        return gate
    seen = worst_where_seen(solution, cov, image_points, image_size, region)
    if seen <= gate.threshold:  # certain where the board was: the views' places are what it lacks
        return gate
    return _scatter_cause(gate, solution, cov.view_factor or 0.0, seen)


def _lens_model_cause(
    gate: GateResult,
    solution: IntrinsicsSolution,
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    region: Region,
    threshold_px: float,
) -> GateResult | None:
    field = diagonal_field_deg(solution.camera_matrix, image_size)
    if solution.model == "fisheye" or field < WIDE_FIELD_DEG:
        return None
    try:
        fisheye = solve_intrinsics(list(object_points), list(image_points), image_size, "fisheye")
    except NumericalError:
        return None
    if not fisheye.rms_px <= (1.0 - FISHEYE_GAIN) * solution.rms_px:
        return None
    better = projection_gate(fisheye, image_size, region, threshold_px)
    then = (
        f"the fisheye model predicts {region.describe()} to {better.value:.3g} px"
        if better.passed
        else f"then, under the fisheye model ({better.value:.3g} px): {better.hint}"
    )
    return replace(
        gate,
        message=f"{gate.message}; the {solution.model} lens model does not fit this {field:.0f} deg lens: "
        f"the fisheye model fits its corners to {fisheye.rms_px:.3f} px against {solution.rms_px:.3f} px",
        reason="projection.lens_model",
        hint=f"calibrate with --model fisheye (or --model auto): the {solution.model} model cannot describe "
        f"this lens, more views will not cure it; {then}",
    )


def _board_cause(
    gate: GateResult, warp: BoardWarp, image_size: tuple[int, int], region: Region, threshold_px: float
) -> GateResult:
    before, after = warp.factors
    bowed = projection_gate(warp.bowed, image_size, region, threshold_px)
    bow_mm = ", ".join(f"{abs(w) * 1e3:.2f} mm along {a}" for w, a in zip(warp.warp_m, "xy", strict=True))
    then = (
        f"with the bow solved the calibration predicts {region.describe()} to {bowed.value:.3g} px"
        if bowed.passed
        else f"then, if it is still uncertain: {gate.hint}"
    )
    return replace(
        gate,
        message=f"{gate.message}; the views scatter as a board that is not flat would: solved with the board "
        f"bowed ({bow_mm} at its centre) the corners fit to {warp.bowed.rms_px:.3f} px against "
        f"{warp.flat.rms_px:.3f} px and the view-level factor falls from {before:.2f} to {after:.2f}",
        reason="projection.board_not_flat",
        hint=f"the board is not flat (it bows {bow_mm} at its centre): mount the print flat on a rigid "
        f"backing (glass, aluminium) and capture again; a richer lens model or more views will not cure "
        f"it; {then}",
        detail={**gate.detail, "board_bow_mm": [f"{w * 1e3:.3f}" for w in warp.warp_m]},
    )


def _scatter_cause(gate: GateResult, solution: IntrinsicsSolution, factor: float, seen: float) -> GateResult:
    """The views disagree beyond their corner noise and neither the lens model, a camera change nor a bowed
    board explains it: the board moved or flexed from view to view (named with its worst views)."""
    rms = np.asarray(solution.per_view_rms_px, np.float64)
    worst = [int(k) + 1 for k in np.argsort(-rms)[:WORST_VIEWS_NAMED]]
    named = ", ".join(f"{k} ({rms[k - 1]:.2f} px)" for k in worst)
    return replace(
        gate,
        message=f"{gate.message}; the views scatter {factor:.2f}x more than their corners' noise explains "
        f"(per-view RMS {rms.min():.2f}-{rms.max():.2f} px; {seen:.3g} px even where the board was seen) and "
        "neither a lens model, a camera change nor a bowed board explains it",
        reason="projection.views_scatter",
        hint=f"the board moved or flexed from view to view (worst views in capture order: {named}): hold a "
        f"rigid board still on a stand for every view and capture again; then, if it is still uncertain: "
        f"{gate.hint}",
        detail={**gate.detail, "worst_views": [str(k) for k in worst]},
    )


def _cells_over(
    sigma: np.ndarray, u: np.ndarray, v: np.ndarray, image_size: tuple[int, int], limit: float
) -> list[str]:
    """Names of the 3 x 3 cells holding a grid point over ``limit``, worst first."""
    w, h = image_size
    ci = np.clip((u / w * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
    ri = np.clip((v / h * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
    worst: dict[tuple[int, int], float] = {}
    for r in range(len(v)):
        for c in range(len(u)):
            if sigma[r, c] > limit:
                key = (int(ri[r]), int(ci[c]))
                worst[key] = max(worst.get(key, 0.0), float(sigma[r, c]))
    return [CELL_NAMES[r][c] for (r, c), _ in sorted(worst.items(), key=lambda kv: -kv[1])]


def session_passed(gates: Sequence[GateResult]) -> bool:
    """The verdict: every gate, tilt and coverage only when there is no projection gate (then they guide)."""
    decided = any(g.gate == "projection" for g in gates)
    return all(g.passed for g in gates if not (decided and g.gate in ADVISORY_GATES))
