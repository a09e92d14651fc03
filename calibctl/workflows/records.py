"""Read-side and field use cases: history, show, export, import, rollback."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import parse_document
from calibctl.artifacts.events import ActivationEvent
from calibctl.config import Settings
from calibctl.errors import InputError, IntegrityError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows import formats

_ARTIFACT_REF = re.compile(r"^(?P<serial>.+?)(?:@(?P<version>[0-9]+))?$")


def parse_artifact_ref(ref: str) -> tuple[str, int | None]:
    """``SERIAL`` or ``SERIAL@N`` -> (serial, version or None for the active one)."""
    match = _ARTIFACT_REF.match(ref.strip())
    if not match or not match.group("serial"):
        raise UsageError(f"'{ref}' is not SERIAL or SERIAL@N")
    version = match.group("version")
    return match.group("serial"), int(version) if version else None


def open_store(settings: Settings) -> Store:
    return Store.open(settings.db_url)


@dataclass
class HistoryRow:
    version: int
    status: str
    active: bool
    rms_px: float
    sigma_fx_px: float | None
    held_out_outer_rms_px: float | None
    station: str
    operator: str
    created_at: str
    board: str
    content_sha256: str
    lint_errors: int


@dataclass
class History:
    serial: str
    active_version: int | None
    versions: list[HistoryRow] = field(default_factory=list)
    events: list[ActivationEvent] = field(default_factory=list)

    def as_json(self) -> dict:
        return {
            "serial": self.serial,
            "active_version": self.active_version,
            "versions": [row.__dict__ for row in self.versions],
            "events": [e.model_dump(mode="json") for e in self.events],
        }


def history(settings: Settings, serial: str) -> History:
    with open_store(settings) as store:
        artifacts = store.list_artifacts(serial)
        active = store.active_version(serial)
        events = store.events(serial)
    rows = [
        HistoryRow(
            version=a.version,
            status=a.status,
            active=a.version == active,
            rms_px=a.rms_px,
            sigma_fx_px=a.stdev.sigma.get("fx"),
            held_out_outer_rms_px=a.held_out.outer_ring_rms_px,
            station=a.provenance.station,
            operator=a.provenance.operator,
            created_at=a.provenance.created_at.isoformat(),
            board=a.board.ref,
            content_sha256=a.content_sha256,
            lint_errors=sum(1 for f in a.lint if f.severity == "error"),
        )
        for a in artifacts
    ]
    return History(serial=serial, active_version=active, versions=rows, events=events)


def show(settings: Settings, ref: str) -> CalibrationArtifact:
    serial, version = parse_artifact_ref(ref)
    with open_store(settings) as store:
        return store.get_artifact(serial, version)


def export(settings: Settings, ref: str, fmt: str, out: Path | None, *, force: bool) -> str:
    """Render ``ref`` (default: the active version) as ``fmt``; write it to ``out`` when given."""
    if fmt not in formats.EXPORT_FORMATS:
        raise UsageError(f"unknown export format '{fmt}'", f"choose one of {', '.join(formats.EXPORT_FORMATS)}")
    art = show(settings, ref)
    text = formats.render(art, fmt)
    if out is not None:
        formats.write_new_file(out, text, force=force)
    return text


def read_artifact_file(path: Path) -> CalibrationArtifact:
    """Parse an exported artifact (JSON or YAML) and check its hash; a tampered file is IntegrityError."""
    data = formats.load_structured_file(path)
    if not formats.looks_like_artifact(data):
        raise InputError(
            f"{path} is not a calibctl artifact (no camera_matrix/content_sha256)",
            "export one with `calibctl export SERIAL --format json`",
        )
    art = parse_document(CalibrationArtifact, data, str(path))
    actual = art.computed_sha256()
    if actual != art.content_sha256:
        raise IntegrityError(
            f"{path}: content does not match its sha256 (recorded {art.content_sha256[:12]}, "
            f"computed {actual[:12]}); the file was changed after export",
            "re-export it from the source store; do not edit artifacts by hand",
        )
    return art


def import_file(settings: Settings, path: Path, *, activate: bool) -> CalibrationArtifact:
    art = read_artifact_file(path)
    with open_store(settings) as store:
        return store.import_artifact(art, actor=settings.operator, station=settings.station, activate=activate)


def rollback(settings: Settings, serial: str, to_version: int, reason: str) -> ActivationEvent:
    if not reason.strip():
        raise UsageError("a rollback needs a reason", "pass --reason 'why this version'")
    with open_store(settings) as store:
        return store.rollback(serial, to_version, reason=reason, actor=settings.operator, station=settings.station)
