"""Key files and trusted-key folders: every bad input is a clear error (exit 2) naming the file."""

from __future__ import annotations

from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ec import SECP256R1, generate_private_key

from calibctl.errors import AlreadyExistsError, FileSystemError, InputError
from calibctl.signing import TrustedKeys, create_key, load_signer, record_message


def _ec_pem(private: bool) -> bytes:
    key = generate_private_key(SECP256R1())
    if private:
        return key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
        )
    return key.public_key().public_bytes(
        serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo
    )


def _private_file(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    path.chmod(0o600)
    return path


def test_a_signature_verifies_only_for_its_message_and_key(tmp_path: Path):
    signer = create_key(tmp_path / "k.pem")
    other = create_key(tmp_path / "other.pem")
    message = record_message("a" * 64, "b" * 64)
    signature = signer.sign(message)
    trusted = TrustedKeys({signer.key_id: signer.public})
    assert trusted.check(signer.key_id, signature, message) is None
    assert "does not match" in (
        trusted.check(signer.key_id, signature, record_message("a" * 64, "c" * 64)) or ""
    )
    assert "not trusted" in (trusted.check(other.key_id, other.sign(message), message) or "")
    assert trusted.check(None, None, message) == "is not signed"
    assert "does not match" in (trusted.check(signer.key_id, "not base64!", message) or "")
    assert load_signer(tmp_path / "k.pem").key_id == signer.key_id


@pytest.mark.parametrize(
    ("content", "expected"),
    [(b"hello", "is not an unencrypted PEM private key"), (None, "not an Ed25519 key")],
)
def test_a_key_file_that_is_not_an_ed25519_private_key(tmp_path: Path, content: bytes | None, expected: str):
    path = _private_file(tmp_path / "k.pem", content if content is not None else _ec_pem(private=True))
    with pytest.raises(InputError, match=expected) as info:
        load_signer(path)
    assert info.value.exit_code == 2 and str(path) in info.value.message


def test_an_unreadable_key_file_and_an_unwritable_key_folder(tmp_path: Path):
    with pytest.raises(FileSystemError, match="cannot read the signing key") as info:
        load_signer(tmp_path)  # a folder
    assert info.value.exit_code == 2
    with pytest.raises(FileSystemError, match="cannot write the signing key"):
        create_key(tmp_path / "missing-folder" / "k.pem")
    create_key(tmp_path / "k.pem")
    with pytest.raises(AlreadyExistsError, match="never overwritten"):
        create_key(tmp_path / "k.pem")
    assert create_key(tmp_path / "k.pem", force=True).key_id  # --force replaces it


def test_trusted_key_folders(tmp_path: Path):
    with pytest.raises(FileSystemError, match="does not exist or is not a folder"):
        TrustedKeys.load(tmp_path / "nope")
    folder = tmp_path / "trusted"
    folder.mkdir()
    (folder / "good.pem").write_text(create_key(tmp_path / "k.pem").public_pem())
    assert len(TrustedKeys.load(folder).keys) == 1
    (folder / "bad.pem").write_text("not a key")
    with pytest.raises(InputError, match="bad.pem is not a PEM public key"):
        TrustedKeys.load(folder)
    (folder / "bad.pem").write_bytes(_ec_pem(private=False))
    with pytest.raises(InputError, match="not an Ed25519 public key"):
        TrustedKeys.load(folder)
