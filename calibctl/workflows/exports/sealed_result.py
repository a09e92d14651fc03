"""A result JSON written outside any store (``lidar solve -o``, ``imu solve -o``), sealed the way a stored
document is.

The file gets ``kind``, ``content_sha256`` (sha256 of the RFC 8785 form of every other field but
``signature``) and, with a signing key configured, ``signature``: the key's Ed25519 signature of
``calibctl-result-v1\\n<kind>\\n<content_sha256>`` with its key id and public key. There is no store record
to sign, so the signature covers the content hash alone; ``lint FILE`` re-derives both.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from calibctl.artifacts.common import jcs_bytes, sha256_hex
from calibctl.signing import ALGORITHM, Signer

LIDAR_RESULT = "lidar-result"
IMU_RESULT = "imu-result"
UNSEALED = ("content_sha256", "signature")


def content_sha256(doc: Mapping[str, Any]) -> str:
    """The hash a sealed result records: every field but the hash and the signature, RFC 8785."""
    return sha256_hex(jcs_bytes({k: v for k, v in doc.items() if k not in UNSEALED}))


def message(kind: str, sha256: str) -> bytes:
    """The bytes a result's signature is taken over."""
    return f"calibctl-result-v1\n{kind}\n{sha256}".encode("ascii")


def seal(doc: Mapping[str, Any], kind: str, signer: Signer | None) -> dict[str, Any]:
    """``doc`` with ``kind`` first, its ``content_sha256`` and (``signer``) its ``signature``."""
    sealed: dict[str, Any] = {"kind": kind, **{k: v for k, v in doc.items() if k not in UNSEALED}}
    sealed["content_sha256"] = content_sha256(sealed)
    if signer is not None:
        sealed["signature"] = {
            "algorithm": ALGORITHM,
            "key_id": signer.key_id,
            "value": signer.sign(message(kind, sealed["content_sha256"])),
            "public_key": signer.public_key_text,
        }
    return sealed
