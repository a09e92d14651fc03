"""Ed25519 signatures on stored records (via the ``cryptography`` package).

A store or station has one key pair. The private key lives in a file outside the database (mode
0600; its path is the ``signing_key`` setting: ``CALIBCTL_SIGNING_KEY`` or the station file); the
public key is exported as PEM and dropped into other systems' trusted-keys folders. Every signature
is stored with its *key id*, the sha256 of the raw public key, so a rotated key's old signatures stay
verifiable as long as its public key stays in the trusted folder. An exported signature also carries
the signer's raw public key (``public_key``, base64): it proves nothing about who signed (anyone can make a
key), but its sha256 must be the key id, so any reader, with trusted keys or none, can tell a signature
that does not match its content (an edit after signing) from a valid one by a key it does not trust.

What is signed is the record's chain hash (which covers every column of the record and the hash of
the record before it) and, for a calibration artifact, its ``content_sha256``, so an exported
artifact can be checked without the store: ``calibctl-record-v1\\n<record_sha256>\\n<subject>``.
"""

from __future__ import annotations

import base64
import hashlib
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # cryptography is imported by the functions that sign or verify: not by every store read
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from calibctl import files
from calibctl.errors import AlreadyExistsError, FileSystemError, InputError

ALGORITHM = "ed25519"
MISMATCH = "does not match its content"
EDITED = "it was edited after signing"


def is_mismatch(problem: str | None) -> bool:
    """Is ``problem`` (a ``TrustedKeys.check`` answer) a signature that does not verify, which every reader
    refuses, keys or not (rather than one that is missing or by an untrusted key)?"""
    return problem is not None and MISMATCH in problem


def _raw(public: Ed25519PublicKey) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return public.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)


def key_id_of(public: Ed25519PublicKey) -> str:
    """The fingerprint stored beside every signature: sha256 of the 32 raw public-key bytes, hex."""
    return hashlib.sha256(_raw(public)).hexdigest()


def public_key_text(public: Ed25519PublicKey) -> str:
    """The raw public key as an exported signature carries it (base64, 44 characters)."""
    return base64.b64encode(_raw(public)).decode("ascii")


def _carried(key_id: str, public_key: str) -> Ed25519PublicKey | None:
    """The public key a signature carries, or None when it is not the key ``key_id`` names."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

    try:
        raw = base64.b64decode(public_key, validate=True)
        key = Ed25519PublicKey.from_public_bytes(raw)
    except ValueError:
        return None
    return key if hashlib.sha256(raw).hexdigest() == key_id else None


def record_message(record_sha256: str, subject: str | None) -> bytes:
    """The bytes a record signature is taken over."""
    return f"calibctl-record-v1\n{record_sha256}\n{subject or ''}".encode("ascii")


@dataclass(frozen=True)
class Signer:
    """A loaded private key."""

    private: Ed25519PrivateKey
    path: Path

    @property
    def public(self) -> Ed25519PublicKey:
        return self.private.public_key()

    @property
    def key_id(self) -> str:
        return key_id_of(self.public)

    def sign(self, message: bytes) -> str:
        return base64.b64encode(self.private.sign(message)).decode("ascii")

    @property
    def public_key_text(self) -> str:
        return public_key_text(self.public)

    def public_pem(self) -> str:
        from cryptography.hazmat.primitives import serialization

        pem = self.public.public_bytes(
            serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo
        )
        return pem.decode("ascii")


def _read(path: Path, what: str) -> bytes:
    try:
        with files.open_regular(path, f"read the {what}") as handle:  # a FIFO is refused, not waited on
            return handle.read()
    except FileNotFoundError as exc:
        raise FileSystemError(
            f"the {what} {path} does not exist",
            "create one with `calibctl keys init`, or fix "
            "the signing_key setting (CALIBCTL_SIGNING_KEY / station file)",
        ) from exc
    except OSError as exc:
        raise FileSystemError(
            f"cannot read the {what} {path}: {exc.strerror}", "check the path and its permissions"
        ) from exc


def load_signer(path: Path) -> Signer:
    """The private key at ``path``; refused when others may read it (as ssh does) or it is not Ed25519."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    data = _read(path, "signing key")
    mode = path.stat().st_mode
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise InputError(
            f"the signing key {path} is readable by others (mode {stat.S_IMODE(mode):o})", f"chmod 600 {path}"
        )
    try:
        key = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError) as exc:
        raise InputError(
            f"{path} is not an unencrypted PEM private key", "create one with `calibctl keys init`"
        ) from exc
    if not isinstance(key, Ed25519PrivateKey):
        raise InputError(
            f"{path} holds a {type(key).__name__}, not an Ed25519 key", "create one with `calibctl keys init`"
        )
    return Signer(key, path)


def create_key(path: Path, *, force: bool = False) -> Signer:
    """Generate a key pair and write the private key to ``path`` with mode 0600 (never wider)."""
    if path.exists() and not force:
        raise AlreadyExistsError(
            f"{path} exists; a signing key is never overwritten by accident",
            "pass --force to replace it (keep its public key trusted: old signatures use it)",
        )
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    key = Ed25519PrivateKey.generate()
    pem = key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )

    try:  # a symlink, FIFO or device at ``path`` is refused, never replaced
        files.write_atomic(path, pem, force=True, fsync=True, mode=0o600)
    except FileSystemError as exc:
        raise FileSystemError(
            exc.message.replace("cannot write ", "cannot write the signing key ", 1), exc.hint
        ) from exc
    return Signer(key, path)


class TrustedKeys:
    """Public keys by key id: the configured key's own, plus every ``*.pem`` in a trusted-keys folder."""

    def __init__(self, keys: dict[str, Ed25519PublicKey] | None = None) -> None:
        self.keys: dict[str, Ed25519PublicKey] = dict(keys or {})

    @classmethod
    def load(cls, folder: Path | None, signer: Signer | None = None) -> TrustedKeys:
        trusted = cls({signer.key_id: signer.public} if signer else {})
        if folder is None:
            return trusted
        from cryptography.hazmat.primitives import serialization
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

        if not folder.is_dir():
            raise FileSystemError(
                f"the trusted-keys folder {folder} does not exist or is not a folder",
                "pass --trusted-keys DIR holding the public keys (`calibctl keys export-public`)",
            )
        for path in sorted(folder.glob("*.pem")):
            try:
                key = serialization.load_pem_public_key(_read(path, "public key"))
            except ValueError as exc:
                raise InputError(
                    f"{path} is not a PEM public key", "export it with `calibctl keys export-public`"
                ) from exc
            if not isinstance(key, Ed25519PublicKey):
                raise InputError(f"{path} holds a {type(key).__name__}, not an Ed25519 public key")
            trusted.keys[key_id_of(key)] = key
        return trusted

    def check(
        self, key_id: str | None, signature: str | None, message: bytes, public_key: str | None = None
    ) -> str | None:
        """None when ``signature`` is a valid signature of ``message`` by a trusted key, else why not.
        ``public_key``: the one the signature carries; with it an untrusted key's signature is verified too,
        so one that does not match (``is_mismatch``) is told from a valid one by a stranger's key."""
        if not signature or not key_id:
            return "is not signed"
        key = self.keys.get(key_id)
        carried = None if public_key is None else _carried(key_id, public_key)
        if public_key is not None and carried is None:
            return f"carries a public key that is not key {key_id[:16]}, so its signature {MISMATCH}"
        verifier = key or carried
        if verifier is None:
            return f"is signed by key {key_id[:16]}, which is not trusted"
        from cryptography.exceptions import InvalidSignature

        try:
            verifier.verify(base64.b64decode(signature, validate=True), message)
        except (InvalidSignature, ValueError):
            return f"has a signature by key {key_id[:16]} that {MISMATCH}"
        return None if key is not None else f"is signed by key {key_id[:16]}, which is not trusted"
