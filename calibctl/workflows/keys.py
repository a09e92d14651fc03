"""Signing keys: create the station's key pair, export its public key, load the keys a command needs.

Without a configured key (``signing_key`` unset) records are written unsigned: a store works as it
always did, ``db verify`` counts the unsigned records, and ``--require-signature`` refuses them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from calibctl.config import Settings
from calibctl.errors import UsageError
from calibctl.files import write_atomic
from calibctl.signing import Signer, TrustedKeys, create_key, load_signer

_NO_KEY_HINT = "set CALIBCTL_SIGNING_KEY or signing_key in the station file, or pass --key FILE"


def signer_of(settings: Settings) -> Signer | None:
    """The configured private key (None when none is configured); an unreadable key is an error."""
    return load_signer(Path(settings.signing_key)) if settings.signing_key else None


def trusted_of(settings: Settings, folder: Path | None = None) -> TrustedKeys:
    """The configured key's public half plus every public key in ``folder`` (or the trusted_keys setting)."""
    chosen = folder or (Path(settings.trusted_keys) if settings.trusted_keys else None)
    return TrustedKeys.load(chosen, signer_of(settings))


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
