"""What a robot sends instead of images: one health report.

A robot in the field runs its own field instruments (seed chapter 6, prompt D: a re-check against the
stored calibration, the gauge, triage, the time-offset estimate) and sends the numbers, one report per
line of a JSON-lines file. ``calibctl fleet ingest`` stores them per serial; ``calibctl fleet trends``
reads them back as conditionals (RMS against temperature, time offset against time), not one aggregate.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field, model_validator

from calibctl.artifacts.common import SERIAL_PATTERN, Document, UtcDatetime, utc_now

HEALTH_REPORT_SCHEMA_VERSION: Literal[1] = 1
MAX_FUTURE = timedelta(minutes=5)
"""A report stamped further ahead than this is refused: the robot's clock is wrong, so is its time axis."""
EARLIEST = datetime(2000, 1, 1, tzinfo=UTC)
"""A report stamped before this is refused: no calibctl calibration was measured then (a robot clock that was
never set reads 1970-01-01, a default date 0001-01-01)."""
SOURCE_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:/@-]{0,127}$"
HealthKind = Literal["check", "gauge", "triage", "timeoffset"]
_NUMBERS: dict[str, tuple[str, ...]] = {
    "check": ("rms_px", "verdict"),
    "gauge": ("ratio", "sigma"),
    "triage": ("verdict",),
    "timeoffset": ("td_ms", "sigma_ms", "temperature_c"),
}
_OPTIONAL = {
    "check": ("temperature_c",),
    "gauge": ("temperature_c",),
    "triage": ("temperature_c",),
    "timeoffset": (),
}


def _a_number(value: Any) -> Any:
    """A JSON number as sent: ``true`` is not 1.0 and ``"0.3"`` is not 0.3 (lax parsing would take both)."""
    if value is None or (isinstance(value, int | float) and not isinstance(value, bool)):
        return value
    raise ValueError(f"must be a number, not {type(value).__name__} {str(value)[:40]}")


Number = Annotated[float, BeforeValidator(_a_number)]
"""A float field of a report: a JSON number only."""


class HealthReport(Document):
    """One robot's report on one serial at one time. Never updated, never deleted."""

    schema_version: Literal[1] = Field(
        HEALTH_REPORT_SCHEMA_VERSION, description="version of this document's schema"
    )
    source_id: str = Field(
        pattern=SOURCE_ID_PATTERN,
        description="the robot's own id for this report, unique in the "
        "store: a report sent twice is refused the second time",
    )
    serial: str = Field(
        pattern=SERIAL_PATTERN,
        description="the camera serial the numbers are about, or the rig's "
        "name for a rig-level report (a rig target's health gate reads those)",
    )
    robot: str = Field(
        pattern=SERIAL_PATTERN, description="the registered robot that carries the serial and sent it"
    )
    time: UtcDatetime = Field(
        description="UTC when the robot measured it; refused more than 5 minutes in the future"
    )
    kind: HealthKind = Field(
        description="check: a re-check against the stored calibration; gauge: the scale "
        "gauge's measured/true ratio; triage: the field triage verdict; timeoffset: the "
        "camera-to-clock time offset estimate"
    )
    rms_px: Number | None = Field(
        None, ge=0, le=1e4, description="check: reprojection RMS of the re-check, px"
    )
    verdict: str | None = Field(
        None,
        pattern=r"^[a-z][a-z0-9_-]{0,31}$",
        description="check: pass | fail; triage: the verdict's name (e.g. ok, intrinsics, extrinsics, time)",
    )
    ratio: Number | None = Field(
        None, gt=0, le=100, description="gauge: measured over true length, dimensionless"
    )
    sigma: Number | None = Field(None, ge=0, le=100, description="gauge: 1-sigma of ratio, dimensionless")
    td_ms: Number | None = Field(
        None, ge=-1e6, le=1e6, description="timeoffset: camera time minus clock time, ms"
    )
    sigma_ms: Number | None = Field(None, ge=0, le=1e6, description="timeoffset: 1-sigma of td_ms, ms")
    temperature_c: Number | None = Field(
        None,
        ge=-100,
        le=200,
        description="the camera's temperature when measured, "
        "degC (required for timeoffset, optional otherwise)",
    )

    @model_validator(mode="after")
    def _shape(self) -> HealthReport:
        if self.time < EARLIEST:
            raise ValueError(
                f"time {self.time.isoformat()} is before {EARLIEST.date()}, when no calibration was measured "
                "(robot clock not set?)"
            )
        if self.time > utc_now() + MAX_FUTURE:
            raise ValueError(
                f"time {self.time.isoformat()} is more than 5 minutes in the future (robot clock?)"
            )
        allowed = _NUMBERS[self.kind] + _OPTIONAL[self.kind]
        missing = [name for name in _NUMBERS[self.kind] if getattr(self, name) is None]
        if missing:
            raise ValueError(
                f"a {self.kind} report needs {', '.join(_NUMBERS[self.kind])}; missing: {', '.join(missing)}"
            )
        for name in ("rms_px", "verdict", "ratio", "sigma", "td_ms", "sigma_ms", "temperature_c"):
            if getattr(self, name) is not None and name not in allowed:
                raise ValueError(f"a {self.kind} report carries {', '.join(allowed)}, not {name}")
        if self.kind == "check" and self.verdict not in ("pass", "fail"):
            raise ValueError("a check report's verdict is pass or fail")
        return self
