"""Import re-derives, never trusts: an artifact from another store gets this store's verdict and version.

A file's ``status`` and ``lint`` are what *its* store decided, under *its* thresholds; anyone can write
``"status": "accepted"`` and recompute the hash. So the numbers are linted again with this store's rules
(the same ``lint_facts`` a solve runs), any capture gate the file records as failed rejects it too, and
the result is this store's verdict. The source ``serial@version`` and its sha256 are kept in
``provenance.imported_from``; the artifact gets this store's next version (``keep_version``: the source
version, only when it is the next one) and a new hash. A rejected import is stored but never activated.

Importing the same content again is a no-op: this store's own export brought back (its content_sha256
is a stored version's) or a source imported before (same serial@version and hash, whatever the file is
called) returns the version it already has, and never activates anything (a rollback since stays).

What signed the source is recorded (``provenance.import_signature``): this store signs the version it
stores with its own key, which says nothing about the file's. A store that requires signatures (it has
keys) never makes an unsigned or untrusted import active by default; ``--activate`` overrides, and the
activation event's reason says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.lint import Finding, has_errors
from calibctl.config import Settings
from calibctl.errors import InconsistentDataError, UsageError
from calibctl.signing import TrustedKeys
from calibctl.store.repository import Store
from calibctl.workflows.lint import evidence
from calibctl.workflows.lint.lint import facts_from_document, lint_facts
from calibctl.workflows.store_admin import keys, records


@dataclass(frozen=True)
class ImportOutcome:
    """What this store made of an imported file."""

    artifact: CalibrationArtifact
    source_ref: str
    source_status: str
    active: bool
    already_imported: bool
    held_back: str | None = None  # why an accepted import was left inactive by the signature rule


def source_label(art: CalibrationArtifact, path: Path) -> str:
    """``CAM@7 sha256 ab12... from station st1 (file x.json)``: enough to find the original again."""
    return f"{art.ref} sha256 {art.content_sha256} from station {art.provenance.station} (file {path.name})"


def rederive(
    art: CalibrationArtifact, settings: Settings, imported_from: str, import_signature: str | None = None
) -> CalibrationArtifact:
    """``art`` with this store's lint findings and verdict, unsealed; ``imported_from`` (and how the source
    was signed) as provenance."""
    findings = lint_facts(facts_from_document(art.model_dump(mode="json"), art.ref), settings.lint)
    failed_gates = [g.gate for g in art.gates if not g.passed]
    if failed_gates:
        findings.append(
            Finding(
                rule="gates",
                severity="error",
                message=f"{art.ref} records failed capture gates ({', '.join(failed_gates)})",
                fix="capture again and solve on this store",
            )
        )
    status = "rejected" if has_errors(findings) else "accepted"
    provenance = art.provenance.model_copy(
        update={"imported_from": imported_from, "import_signature": import_signature}
    )
    return art.model_copy(update={"lint": findings, "status": status, "provenance": provenance})


_EDITED_HINT = (
    "import the artifact as its store exported it; an edited artifact is never trusted, re-sealed or not"
)
FIX_ASPECT_RATIO = 2  # cv2.CALIB_FIX_ASPECT_RATIO (no cv2 import for a number)
TIED_REL_TOL = 1e-9


def check_self_consistent(art: CalibrationArtifact) -> None:
    """InconsistentDataError (exit 1, nothing stored) when the artifact contradicts the solve it names: a
    pinhole solve with CALIB_FIX_ASPECT_RATIO from calibctl's unit start keeps fx / fy at exactly 1 (and
    sigma_fx = sigma_fy), measured 0.0 on every model of the opencv-left-right cameras; a forged fx + 5 px
    with its hash re-sealed imported as accepted and active."""
    tied = art.model.opencv_flags & FIX_ASPECT_RATIO or "CALIB_FIX_ASPECT_RATIO" in art.model.flag_names
    if art.model.name == "fisheye" or not tied:
        return
    fx, fy = art.camera_matrix[0][0], art.camera_matrix[1][1]
    sigma = art.stdev.sigma
    problems = []
    if abs(fx / fy - 1.0) > TIED_REL_TOL:
        problems.append(f"fx {fx:.3f} and fy {fy:.3f} differ")
    if (
        "fx" in sigma
        and "fy" in sigma
        and abs(sigma["fx"] - sigma["fy"]) > TIED_REL_TOL * max(sigma["fy"], 1e-12)
    ):
        problems.append(f"sigma_fx {sigma['fx']:.4g} and sigma_fy {sigma['fy']:.4g} differ")
    if problems:
        raise InconsistentDataError(
            f"{art.ref}: {' and '.join(problems)}, but its model {art.model.name} ties fx to fy "
            "(CALIB_FIX_ASPECT_RATIO): these numbers did not come from the solve it names; nothing was "
            "stored",
            _EDITED_HINT,
        )


def check_evidence(art: CalibrationArtifact) -> None:
    """InconsistentDataError (exit 1, nothing stored) naming every identity the artifact's own numbers break
    (``evidence.evidence_problems``: RMS vs its views and bins, covariance vs sigmas, poses vs image)."""
    problems = evidence.evidence_problems(art)
    if problems:
        raise InconsistentDataError(
            f"{art.ref} does not reproduce its own evidence: {'; '.join(problems)}; nothing was stored",
            _EDITED_HINT,
        )


def _previous_import(store: Store, source: CalibrationArtifact) -> CalibrationArtifact | None:
    """The version this store already holds of the same content: the source itself (this store's own
    export brought back: same content_sha256), or what an earlier import of it (same ref and hash, any
    file name) got."""
    if source.serial not in store.serials():
        return None
    stored = store.list_artifacts(source.serial)
    own = next((a for a in stored if a.content_sha256 == source.content_sha256), None)
    if own is not None:
        return own
    key = f"{source.ref} sha256 {source.content_sha256} "
    return next((a for a in stored if (a.provenance.imported_from or "").startswith(key)), None)


def import_artifact(
    store: Store,
    source: CalibrationArtifact,
    path: Path,
    settings: Settings,
    *,
    activate: bool | None,
    keep_version: bool = False,
    trust: keys.SourceTrust | None = None,
) -> ImportOutcome:
    """Store ``source`` (hash already checked) as this store's next version with this store's verdict.
    ``activate``: None = when accepted and ``trust.may_activate``; True = when accepted (an override of the
    signature rule is recorded in the event's reason); False = never. ``trust`` None: a store without keys."""
    label = source_label(source, path)
    previous = _previous_import(store, source)
    if previous is not None:
        active = store.active_version(source.serial) == previous.version
        return ImportOutcome(previous, source.ref, source.status, active, already_imported=True)
    check_self_consistent(source)
    check_evidence(source)
    if trust is None:
        trust = keys.SourceTrust(keys.signature_mark(source, TrustedKeys())[0], trusted=False, required=False)
    mine = rederive(source, settings, label, trust.mark)
    if keep_version:
        expected = store.next_version(source.serial)
        if source.version != expected:
            raise UsageError(
                f"--keep-version: {source.ref} cannot keep its version here; this store's next version of "
                f"{source.serial} is {expected}",
                "import without --keep-version (the source version is kept in provenance.imported_from)",
            )
    do_activate, override, held_back = trust.activation(mine.status == "accepted", activate)
    stored = store.add_artifact(
        mine,
        activate=do_activate,
        actor=settings.operator,
        station=settings.station,
        reason=f"imported {source.ref}{override}",
        expect_version=source.version if keep_version else None,
    )
    return ImportOutcome(
        stored, source.ref, source.status, do_activate, already_imported=False, held_back=held_back
    )


def import_file(
    settings: Settings,
    path: Path,
    *,
    activate: bool | None,
    keep_version: bool = False,
    require_signature: bool = False,
    trusted_keys: Path | None = None,
) -> ImportOutcome:
    """Check the file's hash and (with ``require_signature``) its signature by a trusted key, then store it
    with this store's verdict and version (see ``imports``)."""
    art = records.read_artifact_file(path)
    trusted = keys.trusted_of(settings, trusted_keys)
    keys.require_trusted(art, str(path), trusted, require_signature)
    trust = keys.source_trust(settings, art, trusted, trusted_keys, require_signature)
    with records.open_store(settings, create=True, write=True) as store:
        return import_artifact(
            store, art, path, settings, activate=activate, keep_version=keep_version, trust=trust
        )
