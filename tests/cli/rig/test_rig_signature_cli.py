"""Rig versions are signed like camera artifacts: `rig solve` with a key signs the version, every rig export
carries the signature (the JSON's `signature`, each header's `calibctl rig-signature` line, the manifest),
`lint --require-signature` checks it (files and `--rig`), and `db verify --require-signature` covers rig
versions."""

from __future__ import annotations

import base64
import json
import shutil

import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
from cryptography.hazmat.primitives.serialization import load_pem_public_key

from calibctl.signing import create_key
from calibctl.store.repository import Store
from calibctl.workflows.exports import trace_header
from tests.artifacts.factories import measured_board
from tests.cli.rig.test_rig_export_cli import db, invoke, rig2, solved  # noqa: F401 - fixtures
from tests.cli.rig.test_rig_store_cli import _capture
from tests.workflows.rig.test_rig_store_flow import WHO, _truth_artifact

SINGLE_FILE_FORMATS = ("json", "opencv", "tf", "urdf", "urdf-joints", "kalibr")


@pytest.fixture(scope="module")
def signed_solved(tmp_path_factory, rig2):
    """A store whose every record (cameras, rig R1@1) is signed by k.pem; trusted/ holds its public key."""
    folder = tmp_path_factory.mktemp("signed")
    key = create_key(folder / "k.pem")
    (folder / "trusted").mkdir()
    (folder / "trusted" / "station.pem").write_text(key.public_pem())
    other = folder / "other"
    other.mkdir()
    (other / "stranger.pem").write_text(create_key(folder / "stranger.pem").public_pem())
    url = f"sqlite:///{folder / 'c.db'}"
    with Store.open(url, signer=key) as store:
        store.add_board(measured_board(square_mm=25.0))
        for name in ("CAM0", "CAM1"):
            store.add_artifact(_truth_artifact(rig2, name), activate=True, **WHO)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("CALIBCTL_SIGNING_KEY", str(folder / "k.pem"))
        assert invoke(url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1").exit_code == 0
        assert _capture(url, rig2).exit_code == 0
        r = invoke(url, "rig", "solve", "R1")
        assert r.exit_code == 0, r.output
    return folder


@pytest.fixture
def signed(signed_solved, tmp_path_factory):
    """A copy of the signed store (url), its trusted folder and a folder holding only a stranger's key."""
    folder = tmp_path_factory.mktemp("signed_copy")
    shutil.copy(signed_solved / "c.db", folder / "c.db")
    return f"sqlite:///{folder / 'c.db'}", signed_solved / "trusted", signed_solved / "other"


def _findings(r, rule="signature"):
    return [f for x in json.loads(r.stdout)["results"] for f in x["findings"] if f["rule"] == rule]


def test_a_signed_rig_version_exports_its_signature_which_verifies_independently(signed, tmp_path):
    url, trusted, _ = signed
    path = tmp_path / "rig.json"
    assert invoke(url, "rig", "export", "R1", "--format", "json", "-o", str(path)).exit_code == 0
    doc = json.loads(path.read_text())
    seal = doc["signature"]
    assert seal["algorithm"] == "ed25519" and set(seal) == {"algorithm", "key_id", "record_sha256", "value"}
    # docs/trust.md's message, checked with cryptography alone: no calibctl code in the check
    public = load_pem_public_key((trusted / "station.pem").read_bytes())
    assert isinstance(public, Ed25519PublicKey)
    message = f"calibctl-record-v1\n{seal['record_sha256']}\n{doc['content_sha256']}".encode("ascii")
    public.verify(base64.b64decode(seal["value"]), message)  # raises InvalidSignature when it does not verify
    r = invoke(url, "--json", "rig", "show", "R1")
    assert json.loads(r.stdout)["signature"] == seal  # the store serves what it exported


def test_every_rig_export_carries_the_signature_and_lints_signed(signed, tmp_path, monkeypatch):
    url, trusted, _ = signed
    monkeypatch.setenv("CALIBCTL_SIGNING_KEY", str(trusted.parent / "k.pem"))  # the bundle's manifest too
    paths = []
    for fmt in SINGLE_FILE_FORMATS:
        paths.append(tmp_path / f"rig.{fmt}")
        assert invoke(url, "rig", "export", "R1", "--format", fmt, "-o", str(paths[-1])).exit_code == 0, fmt
    assert invoke(url, "rig", "export", "R1", "--format", "ros", "-o", str(tmp_path / "ros")).exit_code == 0
    paths += sorted((tmp_path / "ros").iterdir())
    out = tmp_path / "bundle"
    assert invoke(url, "rig", "export", "R1", "--format", "bundle", "-o", str(out)).exit_code == 0
    manifest = json.loads((out / "manifest.json").read_text())
    rig_json = json.loads((out / "rig.json").read_text())
    assert manifest["signature"] == rig_json["signature"] is not None
    assert all(m["signature"] is not None for m in manifest["members"])
    for path in [*paths[1:], *(out / e["path"] for e in manifest["files"] if e["path"] != "rig.json")]:
        header = trace_header.read_rig(path.read_text())
        assert header is not None and header.signature is not None, path
        assert header.signature.model_dump(mode="json") == manifest["signature"], path
    r = invoke(
        url,
        "--json",
        "lint",
        *map(str, paths),
        str(out / "manifest.json"),
        "--require-signature",
        "--trusted-keys",
        str(trusted),
    )
    assert r.exit_code == 0, r.output
    assert _findings(r) == []


def test_a_stranger_key_or_an_edited_signature_line_is_a_signature_error(signed, tmp_path):
    url, trusted, other = signed
    path = tmp_path / "stereo.yaml"
    assert invoke(url, "rig", "export", "R1", "--format", "opencv", "-o", str(path)).exit_code == 0
    r = invoke(url, "--json", "lint", str(path), "--require-signature", "--trusted-keys", str(other))
    assert r.exit_code == 1 and _findings(r)[0]["message"].startswith("rig R1@1 is signed by key ")
    assert "which is not trusted" in _findings(r)[0]["message"]
    text = path.read_text()
    value = next(line for line in text.splitlines() if line.startswith("# calibctl rig-signature ")).rsplit(
        " ", 1
    )[1]
    text = text.replace(value, ("B" if value[0] != "B" else "C") + value[1:])  # a changed signature ...
    text = text.replace(
        trace_header.read_rig(text).file_sha256, trace_header.file_sha256(text)
    )  # ... re-hashed
    path.write_text(text)
    r = invoke(url, "--json", "lint", str(path), "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 1 and "does not match its content" in _findings(r)[0]["message"]


def test_lint_rig_require_signature_passes_a_signed_rig_and_names_an_untrusted_one(signed):
    url, trusted, other = signed
    r = invoke(url, "--json", "lint", "--rig", "R1", "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 0, r.output
    r = invoke(url, "--json", "lint", "--rig", "R1", "--require-signature", "--trusted-keys", str(other))
    assert r.exit_code == 1
    messages = [f["message"] for f in _findings(r)]
    assert [m.split(" is signed by key ")[0] for m in messages] == [
        "rig R1@1",
        "member CAM0@1",
        "member CAM1@1",
    ]
    assert all("which is not trusted" in m for m in messages)


def test_db_verify_require_signature_covers_rig_versions(signed, db, tmp_path):
    """The signed store passes: `rig add` and `rig capture` sign their records too (they wrote them unsigned
    with a key configured, so a signed store's rig definition and rig capture sessions failed this check)."""
    url, trusted, _ = signed
    r = invoke(url, "db", "verify", "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 0, r.output
    key = create_key(tmp_path / "k.pem")
    (tmp_path / "trusted").mkdir()
    (tmp_path / "trusted" / "k.pem").write_text(key.public_pem())
    r = invoke(db, "db", "verify", "--require-signature", "--trusted-keys", str(tmp_path / "trusted"))
    assert r.exit_code == 1 and "rig R1@1 is not signed" in r.output
