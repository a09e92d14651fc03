"""Lint findings: the unit of a calibration verdict."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from calibctl.artifacts.common import Document

Severity = Literal["error", "warning", "info"]


class Finding(Document):
    """One rule's verdict on one calibration. ``error`` fails lint (exit 1); ``warning`` does not."""

    rule: str = Field(description="rule id, e.g. principal-point, sigma-fx, square-size-provenance")
    severity: Severity = Field(description="error fails the calibration, warning is reported")
    message: str = Field(description="what is wrong, with the numbers")
    fix: str | None = Field(None, description="what to do about it")
    value: float | None = Field(None, description="the measured quantity the rule judged, when it has one")
    threshold: float | None = Field(None, description="the limit it was judged against")


def has_errors(findings: list[Finding]) -> bool:
    return any(f.severity == "error" for f in findings)
