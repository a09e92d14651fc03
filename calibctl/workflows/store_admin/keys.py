"""Signing keys: create the station's key pair, export its public key, load the keys a command needs.

Without a configured key (``signing_key`` unset) records are written unsigned: a store works as it
always did, ``db verify`` counts the unsigned records, and ``--require-signature`` refuses them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeVar

from calibctl.config import Settings
from calibctl.errors import FileSystemError, InputError, UsageError
from calibctl.files import write_atomic
from calibctl.signing import (
    EDITED,
    Signer,
    TrustedKeys,
    create_key,
    is_mismatch,
    load_signer,
    public_key_text,
    record_message,
)

if TYPE_CHECKING:  # annotations only: `board list` need not build the calibration models
    from calibctl.artifacts.calibration import CalibrationArtifact, RecordSignature
    from calibctl.artifacts.rig import RigCalibration

_NO_KEY_HINT = "set CALIBCTL_SIGNING_KEY or signing_key in the station file, or pass --key FILE"


def signer_of(settings: Settings) -> Signer | None:
    """The configured private key (None when none is configured); an unreadable key is an error."""
    return load_signer(Path(settings.signing_key)) if settings.signing_key else None


def trusted_of(settings: Settings, folder: Path | None = None) -> TrustedKeys:
    """The configured key's public half plus every public key in ``folder`` (or the trusted_keys setting)."""
    chosen = folder or (Path(settings.trusted_keys) if settings.trusted_keys else None)
    return TrustedKeys.load(chosen, signer_of(settings))


def known_keys(settings: Settings, folder: Path | None = None) -> TrustedKeys:
    """``trusted_of`` where a signature need not be trusted, only checked: no keys when they cannot be
    loaded (a signature carrying its public key is still checked against its content)."""
    try:
        return trusted_of(settings, folder)
    except (FileSystemError, InputError):
        return TrustedKeys()


def read_trust(settings: Settings) -> TrustedKeys | None:
    """The keys a read checks what it serves against (``store.served``): None when the store has no keys
    configured (neither ``signing_key`` nor ``trusted_keys``), so a read checks each record's own hash only.
    A private key this user cannot load (a station's key kept for its service account) is passed over when
    the trusted-keys folder is set: a read needs only public keys."""
    if not settings.signing_key and not settings.trusted_keys:
        return None
    folder = Path(settings.trusted_keys) if settings.trusted_keys else None
    signer = None
    try:
        signer = signer_of(settings)
    except (FileSystemError, InputError):
        if folder is None:  # nothing else to check against: the key's own error (a read needs no private key
            raise  # when the trusted folder holds its public half)
    return TrustedKeys.load(folder, signer)


@dataclass(frozen=True)
class KeyInfo:
    path: str
    key_id: str
    public_pem: str

    def as_json(self) -> dict[str, str]:
        return {"path": self.path, "key_id": self.key_id, "public_pem": self.public_pem}


def _key_path(settings: Settings, key: Path | None) -> Path:
    if key is not None:
        return key
    if not settings.signing_key:
        raise UsageError("no signing key is configured", _NO_KEY_HINT)
    return Path(settings.signing_key)


def init_key(settings: Settings, key: Path | None, *, force: bool) -> KeyInfo:
    """Create a key pair; the private key file gets mode 0600."""
    signer = create_key(_key_path(settings, key), force=force)
    return KeyInfo(str(signer.path), signer.key_id, signer.public_pem())


def export_public(settings: Settings, key: Path | None, out: Path | None, *, force: bool) -> KeyInfo:
    """The public key (PEM) of the signing key; written to ``out`` (e.g. into a trusted-keys folder)."""
    signer = load_signer(_key_path(settings, key))
    if out is not None:
        write_atomic(out, signer.public_pem(), force=force)
    return KeyInfo(str(signer.path), signer.key_id, signer.public_pem())


class Sealed(Protocol):
    """What a store signs and exports with its signature: a camera artifact or a rig version."""

    @property
    def signature(self) -> RecordSignature | None: ...

    @property
    def content_sha256(self) -> str: ...

    @property
    def ref(self) -> str: ...


def seal_problem(seal: RecordSignature | None, content_sha256: str, trusted: TrustedKeys) -> str | None:
    """None when ``seal`` is a valid signature by a trusted key of the record whose content hash is
    ``content_sha256``, else why not (``is not signed`` ...; a mismatch, told by the public key the seal
    carries even when no key is trusted, says it was edited)."""
    if seal is None:
        return "is not signed"
    message = record_message(seal.record_sha256, content_sha256)
    problem = trusted.check(seal.key_id, seal.value, message, seal.public_key)
    return f"{problem}: {EDITED}" if is_mismatch(problem) else problem


SignedT = TypeVar("SignedT", "CalibrationArtifact", "RigCalibration")


def with_public_key(doc: SignedT, known: TrustedKeys | None) -> SignedT:
    """``doc`` whose signature carries its signer's public key, when ``known`` (the store's keys) holds it:
    an export any reader can check for an edit after signing, trusted keys or none."""
    seal = doc.signature
    key = None if seal is None or known is None else known.keys.get(seal.key_id)
    if seal is None or key is None or seal.public_key is not None:
        return doc
    return doc.model_copy(update={"signature": seal.model_copy(update={"public_key": public_key_text(key)})})


def signature_problem(art: Sealed, trusted: TrustedKeys) -> str | None:
    """None when ``art`` carries a valid signature by a trusted key, else why not (``is not signed`` ...)."""
    return seal_problem(art.signature, art.content_sha256, trusted)


def requires_signatures(settings: Settings, folder: Path | None = None) -> bool:
    """Does this store require signatures? Yes once it has keys (a ``signing_key`` or ``trusted_keys``
    configured, or a ``--trusted-keys`` folder given): the same rule by which reads check what they serve."""
    return bool(settings.signing_key or settings.trusted_keys or folder is not None)


def signature_mark(art: Sealed, trusted: TrustedKeys) -> tuple[str, bool]:
    """How ``art`` is signed as ``trusted`` judges it ('trusted key <id>', 'untrusted key <id>', 'unsigned'),
    and whether that is a valid signature by a trusted key. A signature that does not match is refused before
    this."""
    if art.signature is None:
        return "unsigned", False
    ok = signature_problem(art, trusted) is None
    return f"{'trusted' if ok else 'untrusted'} key {art.signature.key_id}", ok


@dataclass(frozen=True)
class SourceTrust:
    """How an imported file is signed (``signature_mark``) and whether this store requires signatures."""

    mark: str
    trusted: bool
    required: bool

    @property
    def may_activate(self) -> bool:
        return self.trusted or not self.required

    def activation(self, acceptable: bool, activate: bool | None) -> tuple[bool, str, str | None]:
        """The import's activation under the signature rule: (activate it, what the activation event's reason
        adds, why an acceptable import is held back or None). ``activate``: None = by the rule; True = also
        unsigned or untrusted (the override is recorded); False = never."""
        do_activate = acceptable and (activate if activate is not None else self.may_activate)
        override = (
            f" ({self.mark}; activated with --activate although this store requires signatures)"
            if do_activate and not self.may_activate
            else ""
        )
        held_back = None
        if acceptable and activate is None and not self.may_activate:
            words = (
                "unsigned"
                if self.mark == "unsigned"
                else f"signed by a key this store does not trust ({self.mark.split()[-1][:16]})"
            )
            held_back = (
                f"imported {words}, not active (this store requires signatures; --activate to override)"
            )
        return do_activate, override, held_back


def source_trust(
    settings: Settings, art: Sealed, trusted: TrustedKeys, trusted_keys: Path | None, require_signature: bool
) -> SourceTrust:
    """``art``'s signature as ``trusted`` judges it, and whether this store requires signatures."""
    mark, ok = signature_mark(art, trusted)
    return SourceTrust(mark, ok, requires_signatures(settings, trusted_keys) or require_signature)


def require_trusted(art: Sealed, source: str, trusted: TrustedKeys, required: bool) -> None:
    """Refuse ``art`` (InputError, exit 2, nothing written) when its signature is required and missing or
    untrusted, and always when it is signed by a trusted key but the signature does not match."""
    problem = signature_problem(art, trusted)
    if problem is None or (not required and not is_mismatch(problem)):
        return
    if required and not trusted.keys:
        raise UsageError(
            "--require-signature needs trusted keys", "pass --trusted-keys DIR or set trusted_keys"
        )
    raise InputError(
        f"{source} ({art.ref}) {problem}",
        "import only what a store whose public key is in --trusted-keys DIR exported",
    )
