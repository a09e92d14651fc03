"""``calibctl rig import``: a rig version exported by another store (its JSON, or a bundle folder) into this
one.

Shaped like the camera ``import`` (workflows.lint.imports): the file's content hash is checked (an edited
file is exit 1), its signature too (``--require-signature``: a trusted key's, exit 2 otherwise; a signature
that does not match is refused always), and the version gets this store's verdict, version, hash and
signature, the source kept in ``provenance.imported_from`` (what signed it in ``import_signature``). A
bundle's every file must be what its rig.json derives (``exports.rig_bundle``), and the version must
reproduce its own evidence (``lint.evidence.rig_evidence_problems``: edges against their transforms, an
unrefined member against its calibration here), else exit 1. Nothing is stored when any check fails.

A rig version pins its members by serial, version and content hash. Each must be in this store: the same
version with the same hash, or this store's import of exactly that version (a camera ``import`` gives it
this store's version and hash, and names the source in its ``imported_from``); the imported rig then pins
this store's member versions. A member not here is exit 2 naming the ``import`` to run first.

The verdict is this store's rig lint (its design baselines, its thresholds, its members' own rules). A
member that is not the active version here makes the rig stale (``rig-stale-member``): that is a fact of
now, not of the calibration, so it is reported and keeps the import from becoming active, but is not
stored as the version's lint. A rejected or stale import is never activated. Importing the same content
again (this store's own export brought back, or a source imported before) is a no-op naming the version.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calibctl import bounded
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import parse_document
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.artifacts.rig import RigCalibration, RigDefinition
from calibctl.config import Settings
from calibctl.errors import InconsistentDataError, InputError, IntegrityError, NotFoundError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.edges.kinds import STALE_RULES, evidence_of
from calibctl.workflows.edges.versions import cal_versions, edge_findings
from calibctl.workflows.exports import bundle, rig_bundle
from calibctl.workflows.lint import evidence
from calibctl.workflows.rig.rig_lint import rig_findings
from calibctl.workflows.store_admin import keys, records

RIG_JSON = rig_bundle.RIG_JSON


@dataclass(frozen=True)
class RigImportOutcome:
    """What this store made of an imported rig version."""

    calibration: RigCalibration
    source_ref: str
    source_status: str
    active: bool
    already_imported: bool
    stale: list[Finding]  # why an accepted import is not active (a member not active here)
    held_back: str | None = None  # why an accepted import was left inactive by the signature rule
    notes: list[Finding] = field(
        default_factory=list
    )  # the bundle's warnings: files its manifest does not list


def _tampered(path: Path, message: str) -> IntegrityError:
    return IntegrityError(
        f"{path}: {message}; nothing was stored",
        "re-export it from the source store (`calibctl rig export RIG@N --format json` or "
        "`--format bundle`); never edit an export by hand",
    )


def _from_bundle(manifest_path: Path) -> tuple[Path, Any, list[Finding]]:
    """The rig.json of a bundle whose files are all present and unchanged, its manifest, and the warnings on
    the folder (what it holds that the manifest does not list)."""
    manifest = bounded.parse_json(bounded.read_text(manifest_path), str(manifest_path))
    if not bundle.is_manifest(manifest):
        raise InputError(
            f"{manifest_path} is not a calibctl bundle manifest",
            "pass a rig JSON export or a folder written by `calibctl rig export --format bundle`",
        )
    found = bundle.check_bundle(manifest_path, manifest)
    problems = [f for f in found if f.severity == "error"]
    if problems:
        raise _tampered(manifest_path, problems[0].message)
    if not any(isinstance(e, dict) and e.get("path") == RIG_JSON for e in manifest.get("files") or []):
        raise _tampered(manifest_path, f"the manifest lists no {RIG_JSON}")
    return manifest_path.parent / RIG_JSON, manifest, [f for f in found if f.severity != "error"]


def read_rig_file(path: Path) -> tuple[RigCalibration, list[Finding]]:
    """The rig version in ``path`` (a rig JSON export, a bundle folder or its manifest.json), its content
    hash checked (IntegrityError, exit 1) and, for a bundle, every listed file and the manifest's own
    claim; and the bundle's warnings (a file in its folder that the manifest does not list)."""
    manifest = None
    notes: list[Finding] = []
    if path.is_dir():
        path = path / bundle.MANIFEST
    manifest_path = path
    if path.name == bundle.MANIFEST:
        path, manifest, notes = _from_bundle(path)
    data = bounded.parse_json(bounded.read_text(path), str(path))
    if not (isinstance(data, dict) and {"rig", "edges", "members", "content_sha256"} <= set(data)):
        raise InputError(
            f"{path} is not a rig version export",
            "pass `calibctl rig export RIG@N --format json` output or a bundle folder",
        )
    cal = parse_document(RigCalibration, data, str(path))
    actual = cal.computed_sha256()
    if actual != cal.content_sha256:
        raise _tampered(
            path,
            f"content does not match its sha256 (recorded {cal.content_sha256[:12]}, computed "
            f"{actual[:12]}): it was changed after export",
        )
    claimed = (
        None
        if manifest is None
        else (manifest.get("rig"), manifest.get("version"), manifest.get("content_sha256"))
    )
    if claimed is not None and claimed != (cal.rig, cal.version, cal.content_sha256):
        raise _tampered(
            path,
            f"the manifest names rig {claimed[0]}@{claimed[1]} sha256 {str(claimed[2])[:12]}, "
            f"{RIG_JSON} is {cal.ref} sha256 {cal.content_sha256[:12]}",
        )
    derived = [] if manifest is None else rig_bundle.check_derived(manifest_path, manifest, cal)
    if derived:  # a file rig.json does not derive: edited numbers (checksums recomputed), swapped cameras
        raise _tampered(manifest_path, derived[0].message)
    return cal, notes


def _import_hint(serial: str, version: int) -> str:
    return (
        f"import the member first: `calibctl export {serial}@{version} --format json -o {serial}.json` on "
        "the "
        f"source store, then `calibctl import {serial}.json` here"
    )


def _member_here(store: Store, serial: str, version: int, sha: str, ref: str) -> CalibrationArtifact:
    """This store's version of a member: the same version and hash, or this store's import of exactly it."""
    stored = store.list_artifacts(serial) if serial in store.serials() else []
    if not stored:
        raise NotFoundError(
            f"member {serial}@{version} of rig {ref} is not in this store; nothing was stored",
            _import_hint(serial, version),
        )
    exact = next((a for a in stored if a.version == version and a.content_sha256 == sha), None)
    key = f"{serial}@{version} sha256 {sha} "
    found = exact or next((a for a in stored if (a.provenance.imported_from or "").startswith(key)), None)
    if found is not None:
        return found
    same = next((a for a in stored if a.version == version), None)
    differs = (
        f"this store's {serial}@{version} is another calibration (sha256 {same.content_sha256[:12]}, the rig "
        f"was solved with {sha[:12]})"
        if same is not None
        else f"this store has no {serial}@{version}"
    )
    raise NotFoundError(
        f"member {serial}@{version} of rig {ref}: {differs} and holds no import of it; nothing was stored",
        _import_hint(serial, version),
    )


def _check_layout(rig: RigDefinition, cal: RigCalibration) -> None:
    """The version's cameras, root and frames are the registered rig's (its design baselines apply)."""
    serials = [m.serial for m in cal.members]
    frames = {f for e in cal.edges for f in (e.parent, e.child)} - set(serials)
    if set(serials) - set(rig.cameras) or cal.root != rig.root or frames - set(rig.frames):
        raise UsageError(
            f"rig {cal.ref} (cameras {', '.join(serials)}, root {cal.root}) is not the rig {rig.name} "
            f"registered here (cameras {', '.join(rig.cameras)}, root {rig.root}); nothing was stored",
            f"import it into a store where {rig.name} is registered with these cameras and root "
            f"(`calibctl rig add {rig.name} --camera {' --camera '.join(serials)}`)",
        )


def _previous(store: Store, source: RigCalibration) -> RigCalibration | None:
    """The version this store holds of the same content: its own export brought back, or an earlier import."""
    try:
        versions = store.list_rig_calibrations(source.rig)
    except NotFoundError:
        return None
    key = f"{source.ref} sha256 {source.content_sha256} "
    return next(
        (
            c
            for c in versions
            if c.content_sha256 == source.content_sha256 or (c.provenance.imported_from or "").startswith(key)
        ),
        None,
    )


def _rederive(
    store: Store, source: RigCalibration, rig: RigDefinition, settings: Settings, label: str, mark: str
) -> tuple[RigCalibration, list[Finding]]:
    """``source`` pinned to this store's members, with this store's lint and verdict; and the stale
    findings."""
    here = {
        m.serial: _member_here(store, m.serial, m.version, m.content_sha256, source.ref)
        for m in source.members
    }
    problems = evidence.rig_evidence_problems(source, here)
    if problems:
        raise InconsistentDataError(
            f"{source.ref} does not reproduce its own evidence: {'; '.join(problems)}; nothing was stored",
            "import the rig version as its store exported it; an edited version is never trusted, "
            "re-sealed or not",
        )
    members = [
        m.model_copy(
            update={"version": here[m.serial].version, "content_sha256": here[m.serial].content_sha256}
        )
        for m in source.members
    ]
    mine = source.model_copy(update={"members": members, "signature": None})
    active: dict[str, CalibrationArtifact | None] = {}
    for serial in here:
        try:
            active[serial] = store.get_artifact(serial, None)
        except NotFoundError:
            active[serial] = None
    findings = rig_findings(mine, rig, active, settings.lint)
    findings += edge_findings(evidence_of(mine), cal_versions(store, mine))
    stale = [f for f in findings if f.rule in STALE_RULES and f.severity == "error"]
    lint = [f for f in findings if f not in stale]
    status = "rejected" if has_errors(lint) else "accepted"
    provenance = source.provenance.model_copy(update={"imported_from": label, "import_signature": mark})
    return mine.model_copy(update={"lint": lint, "status": status, "provenance": provenance}), stale


def import_rig_file(
    settings: Settings,
    path: Path,
    *,
    activate: bool | None,
    require_signature: bool = False,
    trusted_keys: Path | None = None,
) -> RigImportOutcome:
    """Check ``path``'s hash and signature, then store its rig version with this store's verdict and version.

    ``activate``: None = when accepted, no member stale and (a store with keys) signed by a trusted key, as
    the camera ``import`` decides; True = also unsigned or untrusted (recorded in the event's reason); False =
    never."""
    source, notes = read_rig_file(path)
    trusted = keys.trusted_of(settings, trusted_keys)
    keys.require_trusted(source, str(path), trusted, require_signature)
    trust = keys.source_trust(settings, source, trusted, trusted_keys, require_signature)
    label = (
        f"{source.ref} sha256 {source.content_sha256} from station {source.provenance.station} (file "
        f"{path.name})"
    )
    with records.open_store(settings, write=True) as store:  # the rig must be registered: no new store
        rig = store.get_rig(source.rig)
        previous = _previous(store, source)
        if previous is not None:
            active = store.active_rig_version(source.rig) == previous.version
            return RigImportOutcome(
                previous, source.ref, source.status, active, already_imported=True, stale=[], notes=notes
            )
        _check_layout(rig, source)
        mine, stale = _rederive(store, source, rig, settings, label, trust.mark)
        do_activate, override, held_back = trust.activation(mine.status == "accepted" and not stale, activate)
        stored = store.add_rig_calibration(
            mine,
            activate=do_activate,
            actor=settings.operator,
            station=settings.station,
            reason=f"imported rig {source.ref}{override}",
        )
    return RigImportOutcome(
        stored,
        source.ref,
        source.status,
        do_activate,
        already_imported=False,
        stale=stale,
        held_back=held_back,
        notes=notes,
    )
