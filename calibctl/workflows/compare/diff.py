"""``calibctl diff A B``: is B a different calibration from A, beyond both of their uncertainties?

Both refs are read from the store (``SERIAL`` = the active version, ``SERIAL@N`` any version, rejected
ones included and labelled); the numbers are core.compare.projection_diff's. What can be compared:
any two lenses over the same pixel grid, whatever their lens models (by projection); two image
sizes only when the user states the scale between them (``--scale``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.config import Settings
from calibctl.core.compare.lens import Lens
from calibctl.core.compare.projection_diff import (
    ALPHA,
    DEFAULT_GRID,
    UNEXPLAINED_LIMIT_PX,
    DiffField,
    ProjectionDiff,
    projection_diff,
)
from calibctl.errors import NumericalError, UsageError
from calibctl.files import write_atomic
from calibctl.workflows.compare.diff_map import render_map
from calibctl.workflows.store_admin import records


@dataclass(frozen=True)
class DiffRequest:
    """What ``calibctl diff`` was asked: two refs, the range of the compared points (m, inf = rays), the
    scale of B's pixels to A's when their image sizes differ, the sample grid, an optional SVG map."""

    ref_a: str
    ref_b: str
    range_m: float = math.inf
    scale: float | None = None
    grid: tuple[int, int] = DEFAULT_GRID
    map_path: Path | None = None
    force: bool = False


@dataclass
class CameraDiff:
    """The two calibrations, what was compared, the result, and the notes a reader needs."""

    a: CalibrationArtifact
    b: CalibrationArtifact
    scale: float | None
    result: ProjectionDiff
    notes: list[str] = field(default_factory=list)
    map_path: Path | None = None

    @property
    def verdict(self) -> str:
        if self.result.significant is None:
            return "unknown"
        return "different" if self.result.significant else "same"

    def as_json(self) -> dict[str, Any]:
        r = self.result
        return {
            "a": _side(self.a),
            "b": _side(self.b),
            "scale": self.scale,
            "range_m": None if math.isinf(r.range_m) else r.range_m,
            "grid": list(r.grid),
            "samples": len(r.pixels_px),
            "samples_outside_a_model": r.dropped,
            "verdict": self.verdict,
            "reasons": list(r.reasons),
            "alpha": ALPHA,
            "unexplained_limit_px": UNEXPLAINED_LIMIT_PX,
            "raw": _field_json(r.raw),
            "fit": {
                **_field_json(r.fit),
                "rotation_deg": r.rotation_fit_deg,
                "rvec_rad": r.rvec_fit.tolist(),
                "tvec_m": r.tvec_fit_m.tolist(),
            },
            "notes": self.notes,
            "map": None if self.map_path is None else str(self.map_path),
        }


def _side(art: CalibrationArtifact) -> dict[str, Any]:
    return {
        "ref": art.ref,
        "status": art.status,
        "model": art.model.name,
        "image_size": list(art.image_size),
        "content_sha256": art.content_sha256,
        "has_covariance": art.stdev.covariance is not None,
    }


def _field_json(f: DiffField) -> dict[str, Any]:
    out: dict[str, Any] = {"percentiles_px": f.percentiles_px}
    if f.sigma_px is not None and f.z is not None:
        out["expected_sigma_px"] = {"p50": float(np.median(f.sigma_px)), "max": float(f.sigma_px.max())}
        out["z_max"] = float(f.z.max())
    if f.test is not None:
        t = f.test
        out["chi2"] = {
            "statistic": t.statistic,
            "dof": t.dof,
            "p_value": t.p_value,
            "threshold": t.threshold,
            "significant": t.significant,
            "unexplained_max_px": t.unexplained_max_px,
            "unexplained_rms_px": t.unexplained_rms_px,
        }
    return out


def lens_of(art: CalibrationArtifact) -> Lens:
    """The stored calibration as core.compare's Lens (its covariance when it stores one)."""
    cov = art.stdev.covariance
    return Lens(
        np.array(art.camera_matrix, dtype=np.float64),
        np.array(art.dist_coeffs, dtype=np.float64),
        (int(art.image_size[0]), int(art.image_size[1])),
        art.model.name == "fisheye",
        None if cov is None else np.array(cov.matrix, dtype=np.float64),
        () if cov is None else tuple(cov.parameters),
        None if cov is None else cov.aspect_ratio,
        art.model.name,
    )


def check_request(request: DiffRequest) -> None:
    """What diff refuses before it opens the store."""
    if not (request.range_m > 0):
        raise UsageError(
            f"--range-m must be positive, got {request.range_m}", "metres; omit it for rays (infinity)"
        )
    if request.scale is not None and not (math.isfinite(request.scale) and request.scale > 0):
        raise UsageError(f"--scale must be a positive number, got {request.scale}")
    cols, rows = request.grid
    if not (4 <= cols <= 400 and 3 <= rows <= 300):
        raise UsageError(f"--grid {cols}x{rows} is out of range", "from 4x3 to 400x300 samples")


def _pixel_frames(a: CalibrationArtifact, b: CalibrationArtifact, lens_b: Lens, scale: float | None) -> Lens:
    (wa, ha), (wb, hb) = a.image_size, b.image_size
    if scale is None:
        if (wa, ha) != (wb, hb):
            raise UsageError(
                f"{a.ref} is {wa}x{ha} and {b.ref} is {wb}x{hb}: projections on different pixel grids "
                "cannot be "
                "compared without the scale between them",
                f"if {b.ref} is the same sensor read out at another resolution, pass --scale S (its pixels "
                "times S "
                f"are {a.ref}'s; here S = {wa / wb:g} if the whole sensor is read out in both)",
            )
        return lens_b
    if (round(wb * scale), round(hb * scale)) != (wa, ha):
        raise UsageError(
            f"--scale {scale:g} makes {b.ref}'s {wb}x{hb} into {round(wb * scale)}x{round(hb * scale)}, "
            f"not {a.ref}'s {wa}x{ha}",
            f"pass the scale of the readouts, here {wa / wb:g}",
        )
    return lens_b.scaled(scale)


def diff_cameras(settings: Settings, request: DiffRequest) -> CameraDiff:
    """Compare two stored camera calibrations (``SERIAL[@N]`` each)."""
    check_request(request)
    return compare_artifacts(
        records.show(settings, request.ref_a), records.show(settings, request.ref_b), request
    )


def compare_artifacts(a: CalibrationArtifact, b: CalibrationArtifact, request: DiffRequest) -> CameraDiff:
    """``diff_cameras`` of two calibrations read already (a rollout reads all its targets in one store
    session)."""
    if a.serial == b.serial and a.version == b.version:
        raise UsageError(
            f"{request.ref_a} and {request.ref_b} are both {a.ref}: there is nothing to compare",
            "name two different versions (e.g. CAM@3 CAM@4; `calibctl history SERIAL` lists them)",
        )
    lens_a = lens_of(a)
    lens_b = _pixel_frames(a, b, lens_of(b), request.scale)
    notes = [
        f"{art.ref} is a REJECTED calibration (compared as asked; a robot must not load it)"
        for art in (a, b)
        if art.status == "rejected"
    ]
    if a.model.name != b.model.name:
        notes.append(
            f"different lens models ({a.model.name} and {b.model.name}): compared by projection; their "
            "parameters cannot be compared one by one, and a difference neither model's noise can "
            "produce is reported as unexplained"
        )
    if request.scale is not None:
        notes.append(f"{b.ref} scaled by {request.scale:g} into {a.ref}'s pixels")
    try:
        result = projection_diff(lens_a, lens_b, request.grid, request.range_m)
    except ValueError as exc:
        raise NumericalError(
            f"cannot compare {a.ref} and {b.ref}: {exc}",
            "the two lens models share almost no part of the image",
        ) from exc
    if a.model.name != b.model.name and result.dropped:
        notes.append(
            f"compared over the region both lenses map: {len(result.pixels_px)} of "
            f"{len(result.pixels_px) + result.dropped} samples; the rest of {a.ref}'s image ({a.model.name}) "
            f"falls outside what {b.ref} ({b.model.name}) maps into its image"
        )
    out = CameraDiff(a, b, request.scale, result, notes)
    if request.map_path is not None:
        write_atomic(
            request.map_path, render_map(out.a.ref, out.b.ref, lens_a.image_size, result), force=request.force
        )
        out.map_path = request.map_path
    return out
