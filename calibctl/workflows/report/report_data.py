"""What a calibration report page draws, gathered from the store: the types ``report`` fills and
``report_html`` renders (kept apart so the renderer never imports the gatherer)."""

from __future__ import annotations

from dataclasses import dataclass

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
class ReportData:
    artifact: CalibrationArtifact
    active: bool
    views: list[ViewCorners]  # empty when the session is not in this store (an imported artifact)
    corners_note: str | None  # why there are no corners to draw, else None
    uncertainty: report_maps.UncertaintyMap | None
    distortion: tuple[np.ndarray, np.ndarray]
