"""Read-side and field use cases: history, show, export, rollback (import is ``workflows.lint.imports``:
it lints what it lets in)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from calibctl import bounded
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.check import CheckEvent
from calibctl.artifacts.common import MAX_VERSION, parse_document
from calibctl.artifacts.events import ActivationEvent
from calibctl.config import Settings
from calibctl.errors import InputError, IntegrityError, UsageError
from calibctl.files import write_atomic
from calibctl.store import sqlite_reads

if TYPE_CHECKING:
    from calibctl.store.repository import Store

_KIND_NAMES = {"ros": "a ROS camera_info export", "opencv": "an OpenCV FileStorage export"}
_ARTIFACT_REF = re.compile(r"^(?P<serial>.+?)(?:@(?P<version>[0-9]+))?$")


def parse_artifact_ref(ref: str) -> tuple[str, int | None]:
    """``SERIAL`` or ``SERIAL@N`` -> (serial, version or None for the active one)."""
    match = _ARTIFACT_REF.match(ref.strip())
    if not match or not match.group("serial"):
        raise UsageError(f"'{ref}' is not SERIAL or SERIAL@N")
    serial, at, version_text = ref.strip().rpartition("@")
    if at and serial and not version_text.isdecimal():
        raise UsageError(
            f"'{ref}' is not SERIAL or SERIAL@N: the version '{version_text}' is not a whole number",
            f"name a version by its number (e.g. {serial}@3; `calibctl history {serial}` lists them), "
            f"or drop @... for the active one",
        )
    version = match.group("version")
    if version and (len(version) > 10 or int(version) > MAX_VERSION):
        raise UsageError(
            f"'{ref}': version {version[:20]} is out of range", f"versions go from 1 to {MAX_VERSION}"
        )
    return match.group("serial"), int(version) if version else None


def open_store(settings: Settings, *, create: bool = False, write: bool = False) -> Store:
    """The configured store. Read commands pass ``create=False``: a mistyped ``--db`` is an error, never a
    new empty store that answers "nothing here" (or lets ``lint --all`` pass with nothing checked).
    Commands that write pass ``write=True``: the configured signing key is loaded (and must be readable).
    With keys configured, what either reads is checked as ``db verify`` would (``store.served``): a write
    never builds on a record a read would refuse."""
    from calibctl.store.repository import Store  # sqlalchemy: history/show/export of SQLite use sqlite_reads
    from calibctl.workflows.store_admin import keys

    return Store.open(
        settings.db_url,
        create=create,
        signer=keys.signer_of(settings) if write else None,
        trusted=keys.read_trust(settings),
    )


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
    checks: list[CheckEvent] = field(default_factory=list)

    def as_json(self) -> dict:
        return {
            "serial": self.serial,
            "active_version": self.active_version,
            "versions": [row.__dict__ for row in self.versions],
            "events": [e.model_dump(mode="json") for e in self.events],
            "checks": [c.model_dump(mode="json") for c in self.checks],
        }


def history(settings: Settings, serial: str) -> History:
    artifacts, active, events, checks = sqlite_reads.read(
        settings.db_url,
        lambda store: (
            store.list_artifacts(serial),
            store.active_version(serial),
            store.events(serial),
            store.checks(serial),
        ),
        lambda: open_store(settings),
    )
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
    return History(serial=serial, active_version=active, versions=rows, events=events, checks=checks)


def show(settings: Settings, ref: str) -> CalibrationArtifact:
    from calibctl.workflows.store_admin import keys  # the trusted keys: `history` reads without them

    serial, version = parse_artifact_ref(ref)
    return sqlite_reads.read(
        settings.db_url,
        lambda store: store.get_artifact(serial, version),
        lambda: open_store(settings),
        keys.read_trust(settings),
    )


def _refuse_rejected(art: CalibrationArtifact, allow_rejected: bool) -> None:
    if art.status == "rejected" and not allow_rejected:
        raise UsageError(
            f"{art.ref} is a rejected calibration; a robot must not load it",
            "export an accepted version (see `calibctl history`), or pass --allow-rejected to inspect it "
            "(the export then says it is rejected)",
        )


def export(
    settings: Settings,
    ref: str,
    fmt: str,
    out: Path | None,
    *,
    force: bool,
    allow_rejected: bool = False,
    camera_name: str | None = None,
    lut_options: bool = False,
    topic: str | None = None,
) -> str:
    """Render ``ref`` (default: the active version) as ``fmt``; write it to ``out`` when given.

    A rejected version is refused unless ``allow_rejected`` (exit 2: nothing was exported, the
    command could not do what was asked; there is no verdict to report). Every export names the
    version's status: a field in json/yaml, the trace header in ros/opencv. ``lut_options``: --alpha or
    --balance was given, which only ``export_lut`` takes.
    """
    from calibctl.workflows.exports import formats  # the writers: not for history or show

    if fmt not in formats.EXPORT_FORMATS:
        raise UsageError(
            f"unknown export format '{fmt}'", f"choose one of {', '.join(formats.EXPORT_FORMATS)}"
        )
    if camera_name is not None and fmt != "ros":
        raise UsageError("--camera-name applies to --format ros only")
    if topic is not None:
        topic = _kalibr_topic(topic, fmt)
    if lut_options:
        raise UsageError("--alpha and --balance apply to --format lut only")
    art = _exported(settings, ref)
    _refuse_rejected(art, allow_rejected)
    text = formats.render(art, fmt, camera_name=camera_name, topic=topic)
    if fmt in formats.HEADER_FORMATS:  # signed as written where a key is configured: the artifact's
        from calibctl.workflows.exports import trace_header  # signature does not cover the file's numbers
        from calibctl.workflows.store_admin import keys

        text = trace_header.sign_file(text, keys.signer_of(settings))
    if out is not None:
        write_atomic(out, text, force=force)
    return text


def _kalibr_topic(topic: str, fmt: str) -> str:
    """``--topic``: Kalibr's rostopic, a legal ROS name with one leading ``/`` (UsageError otherwise)."""
    from calibctl.workflows.exports.frame_names import NAME_RULE, is_ros_name

    if fmt != "kalibr":
        raise UsageError("--topic applies to --format kalibr only", "--camera-name names a ros export")
    name = topic.removeprefix("/")
    if not is_ros_name(name):
        raise UsageError(f"--topic {topic!r} is not a legal ROS topic", f"{NAME_RULE}; e.g. /cam0/image_raw")
    return f"/{name}"


def _exported(settings: Settings, ref: str) -> CalibrationArtifact:
    """``ref`` as an export carries it: its signature with the signer's public key, when this store has it."""
    from calibctl.workflows.store_admin import keys

    return keys.with_public_key(show(settings, ref), keys.read_trust(settings))


def _free_parameter(lens: str, alpha: float | None, balance: float | None) -> float:
    """alpha (pinhole) or balance (fisheye), 0 to 1, default 0; the other lens's option is refused."""
    given, wrong = (balance, alpha) if lens == "fisheye" else (alpha, balance)
    if wrong is not None:
        name, other = ("--alpha", "--balance") if lens == "fisheye" else ("--balance", "--alpha")
        raise UsageError(f"{name} applies to the other lens model (this is a {lens} lens)", f"pass {other}")
    value = 0.0 if given is None else float(given)
    if not 0.0 <= value <= 1.0:
        name = "--balance" if lens == "fisheye" else "--alpha"
        raise UsageError(
            f"{name} {value} is outside 0..1", "0 keeps only valid pixels, 1 keeps every source pixel"
        )
    return value


def export_lut(
    settings: Settings,
    ref: str,
    out: Path | None,
    *,
    force: bool,
    allow_rejected: bool = False,
    alpha: float | None = None,
    balance: float | None = None,
    camera_name: str | None = None,
    topic: str | None = None,
) -> list[Path]:
    """The undistortion maps of ``ref`` (default: the active version) into the new folder ``out``
    (workflows.exports.lut); a rejected version is refused unless ``allow_rejected``, as for every export."""
    from calibctl.workflows.exports import formats, lut, trace_header
    from calibctl.workflows.exports.frame_names import default_frame

    if camera_name is not None:
        raise UsageError("--camera-name applies to --format ros only")
    if topic is not None:
        _kalibr_topic(topic, "lut")
    if out is None:
        raise UsageError("--format lut writes a folder of maps", "pass -o DIR (a new folder)")
    art = _exported(settings, ref)
    _refuse_rejected(art, allow_rejected)
    lens: Literal["pinhole", "fisheye"] = "fisheye" if art.model.name == "fisheye" else "pinhole"
    camera = lut.single_camera(
        art.serial,
        art.version,
        art.content_sha256,
        default_frame(art.serial, camera=False),
        lens,
        art.camera_matrix,
        art.dist_coeffs,
        art.image_size,
        _free_parameter(lens, alpha, balance),
    )
    payloads, entries = lut.build([camera])
    payloads[lut.CAMERA_DOCUMENT] = formats.render(art, "json").encode("utf-8")
    source = lut.source_of("camera", art.ref, art.status, art.content_sha256, payloads[lut.CAMERA_DOCUMENT])
    header = trace_header.stamp(art, lut.header_body(source, entries), signed=True)
    return lut.write_lut(out, payloads, header, force=force)


def read_artifact_file(path: Path) -> CalibrationArtifact:
    """Parse an exported artifact (JSON or YAML) and check its hash; a tampered file is IntegrityError."""
    from calibctl.workflows.exports import formats

    loaded = formats.load_calibration(path)
    if loaded.kind != "calibctl":
        raise InputError(
            f"{path} is {_KIND_NAMES[loaded.kind]}: it holds the numbers a robot needs, not the whole "
            "artifact",
            "import the artifact itself: `calibctl export SERIAL --format json` on the source store",
        )
    art = parse_document(CalibrationArtifact, loaded.data, str(path))
    actual = art.computed_sha256()
    if actual != art.content_sha256:
        raise IntegrityError(
            f"{path}: content does not match its sha256 (recorded {art.content_sha256[:12]}, "
            f"computed {actual[:12]}); the file was changed after export",
            "re-export it from the source store; do not edit artifacts by hand",
        )
    return art


MAX_REASON_CHARS = 2000


def check_rollback_request(to_version: int, reason: str) -> None:
    """What a rollback (camera or rig) refuses before it opens the store: no reason, a reason with
    control characters, a version out of range."""
    if not reason.strip():
        raise UsageError("a rollback needs a reason", "pass --reason 'why this version'")
    bounded.check_text(reason, "--reason", "the reason")
    if len(reason) > MAX_REASON_CHARS:  # kept forever in the chained event log, printed in every history
        raise UsageError(
            f"the reason is {len(reason)} characters long (at most {MAX_REASON_CHARS})",
            "say why in a sentence or two; put long notes in the ticket the reason names",
        )
    if not 1 <= to_version <= MAX_VERSION:
        raise UsageError(f"version {to_version} is out of range", f"versions go from 1 to {MAX_VERSION}")


def rollback(
    settings: Settings, serial: str, to_version: int, reason: str, expected_active: int | None = None
) -> ActivationEvent | None:
    """Roll back as a compare-and-set: against ``expected_active`` (what the technician saw) when given,
    else against the active version read first; a change in between refuses the rollback. None when
    ``to_version`` is the active version already (nothing written: a retried rollback is done)."""
    check_rollback_request(to_version, reason)
    with open_store(settings, write=True) as store:
        seen = store.active_version(serial) if expected_active is None else expected_active
        return store.rollback(
            serial,
            to_version,
            reason=reason,
            actor=settings.operator,
            station=settings.station,
            expected_active=seen,
        )
