"""What a calibration report page draws, gathered from the store: the types ``report`` fills and
``report_html`` renders (kept apart so the renderer never imports the gatherer)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.core.intrinsics import report_maps


@dataclass(frozen=True)
class ViewCorners:
    """One solved view's corners as the report draws them."""

    name: str
    corners_px: np.ndarray  # (N, 2) float64
    residuals_px: np.ndarray  # (N, 2) float64, observed - projected under the stored model and pose
    outlier: bool
    dropped: bool


@dataclass(frozen=True)
class DiffSection:
    """``calibctl diff`` of the previous accepted version against this one (the compare room fills it)."""

    previous_ref: str
    verdict: str  # same, different, unknown (no covariance to judge by)
    raw_px: dict[str, float]  # |difference| percentiles without re-fitting the camera frame
    fit_px: dict[str, float]  # after fitting the implied rotation (mrcal's projection diff)
    rotation_deg: float
    expected_sigma_px: (
        float | None
    )  # the median expected one-sigma of the raw difference, from both covariances
    reasons: tuple[str, ...]


@dataclass(frozen=True)
class ReportData:
    artifact: CalibrationArtifact
    active: bool
    views: list[ViewCorners]  # empty when the session is not in this store (an imported artifact)
    corners_note: str | None  # why there are no corners to draw, else None
    uncertainty: report_maps.UncertaintyMap | None
    distortion: tuple[np.ndarray, np.ndarray]
    diff: DiffSection | None = None  # against the previous accepted version, when there is one
    diff_note: str | None = None  # why there is no diff section
    trends: dict[str, Any] | None = None  # ``fleet trends``' JSON, when robots reported on this serial
