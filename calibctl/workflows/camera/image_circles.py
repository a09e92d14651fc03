"""``--image-circle CX,CY,R`` of capture, calibrate and solve: parsed, checked against the image, recorded.

The circle itself (detection from the frames, the cells it covers) is calibctl.core.capture.image_circle; a
session records it in its coverage gate's detail, and a calibration carries its session's gates, so
lint reads it back from there (the fold-over check then stops at the circle).
"""

from __future__ import annotations

import numpy as np

from calibctl.artifacts.session import GateResult
from calibctl.core.capture.image_circle import ImageCircle, circle_detail, circle_problem
from calibctl.errors import UsageError

__all__ = ["checked_image_circle", "parse_image_circle", "with_circle"]


def parse_image_circle(text: str | None) -> tuple[float, float, float] | None:
    """``--image-circle CX,CY,R`` (pixels) -> (cx, cy, r); None for None. Raises UsageError (exit 2)."""
    if text is None:
        return None
    parts = text.replace(" ", "").split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(np.isfinite(values)):
        raise UsageError(
            f"--image-circle '{text}' is not CX,CY,R", "three numbers in pixels, e.g. 640,480,470"
        )
    if values[2] <= 0:
        raise UsageError(
            f"--image-circle '{text}': the radius must be positive, got {values[2]:g} px",
            "three numbers in pixels, e.g. 640,480,470",
        )
    return values[0], values[1], values[2]


def checked_image_circle(circle: tuple[float, float, float], image_size: tuple[int, int]) -> ImageCircle:
    """A given circle that fits the (W, H) image, or UsageError (exit 2) with the numbers."""
    problem = circle_problem(circle, image_size)
    if problem is not None:
        raise UsageError(
            f"--image-circle: {problem}",
            "give the image circle in pixels of the frames (CX,CY = its centre, R = its radius), "
            "or leave the option out to find it in the frames",
        )
    return ImageCircle(*circle, source="given")


def with_circle(gates: list[GateResult], circle: ImageCircle) -> list[GateResult]:
    """The gates with ``circle`` recorded in the coverage gate's detail (a solve's --image-circle)."""
    return [
        g.model_copy(update={"detail": {**g.detail, **circle_detail(circle)}}) if g.gate == "coverage" else g
        for g in gates
    ]
