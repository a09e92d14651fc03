"""What the robot loads is what was signed: every file of a bundle is derived from its verified rig.json, so
the forgeries a text editor makes without the key (an fx moved with its checksums recomputed, two camera
files swapped, an edge or a member's fx edited inside a re-hashed, unsigned rig.json, a signature that does
not match) are refused by `calibctl lint` and by `rig import`, on both store backends."""

from __future__ import annotations

import hashlib
import json
import re

import pytest

from calibctl.workflows.exports import trace_header
from tests.cli.rig.test_rig_export_cli import db, invoke, rig2, solved  # noqa: F401 - fixtures
from tests.cli.rig.test_rig_import_cli import _rig_versions
from tests.cli.rig.test_rig_signature_cli import signed, signed_solved  # noqa: F401 - fixtures


def _text(r):
    return " ".join(r.output.split())


def _bundle(url, folder, *args):
    r = invoke(url, "rig", "export", "R1", "--format", "bundle", "-o", str(folder), *args)
    assert r.exit_code == 0, r.output
    return folder


@pytest.fixture
def keyed(signed, monkeypatch):
    """The signed store with its key configured (`rig export --format bundle` signs the manifest)."""
    monkeypatch.setenv("CALIBCTL_SIGNING_KEY", str(signed[1].parent / "k.pem"))
    return signed


def _reseal(folder, name, text):
    """What a forger does: write the file, recompute its file-sha256 line and its manifest entry."""
    body = "".join(line for line in text.splitlines(keepends=True) if "calibctl file-sha256 " not in line)
    stamped = re.sub(
        r"(# calibctl file-sha256 )[0-9a-f]{64}",
        lambda m: m.group(1) + trace_header.file_sha256(body),
        text,
    )
    (folder / name).write_text(stamped)
    if not (folder / "manifest.json").exists():
        return
    manifest = json.loads((folder / "manifest.json").read_text())
    for entry in manifest["files"]:
        if entry["path"] == name:
            data = stamped.encode()
            entry.update(sha256=hashlib.sha256(data).hexdigest(), bytes=len(data))
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=2))


def _rehash_rig(doc):
    """A rig.json edited, its content hash recomputed and its signature dropped (no key needed)."""
    from calibctl.artifacts.rig import RigCalibration

    doc.pop("signature", None)
    cal = RigCalibration.model_validate(doc)
    doc["content_sha256"] = cal.computed_sha256()
    return doc


def _target(source, url, tmp_path):
    """``url``: a store holding `calibctl import`s of the source's members, rig R1 registered."""
    for cam in ("CAM0", "CAM1"):
        path = tmp_path / f"{cam}.json"
        assert invoke(source, "export", cam, "-o", str(path)).exit_code == 0
        assert invoke(url, "import", str(path)).exit_code == 0
    assert invoke(url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1").exit_code == 0
    return url


def _lint(folder, trusted, *extra):
    args = ["lint", str(folder / "manifest.json"), "--require-signature", "--trusted-keys", str(trusted)]
    return invoke("sqlite:///unused.db", *args, *extra)


def test_an_honest_signed_bundle_lints_clean_and_imports(keyed, db_url, tmp_path):
    source, trusted, _ = keyed
    folder = _bundle(source, tmp_path / "bundle")
    r = _lint(folder, trusted)
    assert r.exit_code == 0, r.output
    url = _target(source, db_url, tmp_path)
    r = invoke(url, "--json", "rig", "import", str(folder), "--trusted-keys", str(trusted))
    assert r.exit_code == 0, r.output
    got = json.loads(invoke(url, "--json", "rig", "show", "R1").stdout)
    assert got["provenance"]["import_signature"].startswith("trusted key ")


def test_an_fx_edited_with_its_checksums_recomputed_is_refused_by_lint_and_import(signed, db_url, tmp_path):
    source, trusted, _ = signed
    folder = _bundle(source, tmp_path / "bundle")
    text = (folder / "cam1.yaml").read_text()
    fx = re.search(r"camera_matrix:\n  rows: 3\n  cols: 3\n  data: \[([-0-9.e+]+)", text).group(1)
    _reseal(folder, "cam1.yaml", text.replace(f"data: [{fx}", f"data: [{float(fx) + 1.0!r}", 1))
    r = invoke("sqlite:///unused.db", "lint", str(folder / "manifest.json"))
    assert r.exit_code == 1 and "was changed after calibctl wrote it" not in _text(r)
    assert f"{folder / 'cam1.yaml'} differs from what rig.json (R1@1) derives for it" in _text(r)
    assert _lint(folder, trusted).exit_code == 1
    url = _target(source, db_url, tmp_path)
    r = invoke(url, "rig", "import", str(folder))
    assert r.exit_code == 1 and "differs from what rig.json" in _text(r) and "nothing was stored" in _text(r)
    assert _rig_versions(url) == []


def test_swapped_camera_files_are_refused_naming_the_role(signed, db_url, tmp_path):
    source, trusted, _ = signed
    folder = _bundle(source, tmp_path / "bundle")
    left, right = (folder / "cam0.yaml").read_text(), (folder / "cam1.yaml").read_text()
    _reseal(folder, "cam0.yaml", right)
    _reseal(folder, "cam1.yaml", left)
    r = _lint(folder, trusted)
    assert r.exit_code == 1
    assert f"{folder / 'cam0.yaml'} holds what rig.json derives for cam1.yaml" in _text(r)
    url = _target(source, db_url, tmp_path)
    r = invoke(url, "rig", "import", str(folder), "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 1 and "holds what rig.json derives for cam1.yaml" in _text(r)
    assert _rig_versions(url) == []


def test_a_manifest_claiming_other_roles_is_refused(signed, tmp_path):
    source, trusted, _ = signed
    folder = _bundle(source, tmp_path / "bundle")
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["members"][0]["camera_info"], manifest["members"][1]["camera_info"] = "cam1.yaml", "cam0.yaml"
    (folder / "manifest.json").write_text(json.dumps(manifest))
    r = _lint(folder, trusted)
    assert r.exit_code == 1 and "'members' is" in _text(r) and "but rig.json (R1@1) derives" in _text(r)


@pytest.mark.parametrize("forgery", ["edge", "member-fx"])
def test_a_rehashed_unsigned_rig_json_that_contradicts_itself_is_refused_in_a_keyless_store(
    signed, db_url, tmp_path, forgery
):
    source, _, _ = signed
    path = tmp_path / "R1.json"
    assert invoke(source, "rig", "export", "R1", "--format", "json", "-o", str(path)).exit_code == 0
    doc = json.loads(path.read_text())
    if forgery == "edge":  # the baseline 10 mm longer, its translation_mm left as it was
        doc["edges"][0]["T_parent_child"][0][3] -= 0.010
        expected = "translation_mm"
    else:  # the right camera's fx inside the rig, 5 px more: not what its calibration says
        K = doc["members"][1]["camera_matrix"]
        K[0][0] += 5.0
        expected = "was not refined by the rig solve, yet its K or distortion"
    path.write_text(json.dumps(_rehash_rig(doc)))
    r = invoke("sqlite:///unused.db", "lint", str(path))
    if forgery == "edge":  # lint has no store: the member's own calibration is `rig import`'s to compare
        assert r.exit_code == 1 and "does not reproduce its own evidence" in _text(r)
    url = _target(source, db_url, tmp_path)  # no key, no trusted keys
    r = invoke(url, "rig", "import", str(path))
    assert r.exit_code == 1, r.output
    assert "does not reproduce its own evidence" in _text(r) and expected in _text(r)
    assert "nothing was stored" in _text(r)
    assert _rig_versions(url) == []


def test_a_signature_that_does_not_match_is_refused_by_lint_and_import(signed, db_url, tmp_path):
    source, trusted, _ = signed
    folder = _bundle(source, tmp_path / "bundle")
    doc = json.loads((folder / "rig.json").read_text())
    doc["pairs"][0]["shared_views"] += 1  # any change: the hash recomputed, the old signature kept
    signature = doc["signature"]
    doc = _rehash_rig(doc)
    doc["signature"] = signature
    path = tmp_path / "R1.json"
    path.write_text(json.dumps(doc))
    r = invoke(
        "sqlite:///unused.db", "lint", str(path), "--require-signature", "--trusted-keys", str(trusted)
    )
    assert r.exit_code == 1 and "does not match its content" in _text(r)
    url = _target(source, db_url, tmp_path)
    r = invoke(url, "rig", "import", str(path), "--trusted-keys", str(trusted))
    assert r.exit_code == 2 and "does not match its content" in _text(r)
    assert _rig_versions(url) == []


def test_a_signature_that_does_not_match_is_refused_in_a_keyless_store(keyed, db_url, tmp_path, monkeypatch):
    """The exported signature carries its public key: a reader with no trusted keys still tells an edit
    after signing (refused) from an honest version by a key it does not trust (stored, not trusted)."""
    source, _, _ = keyed
    folder = _bundle(source, tmp_path / "bundle")
    honest = json.loads((folder / "rig.json").read_text())
    doc = json.loads((folder / "rig.json").read_text())
    doc["pairs"][0]["shared_views"] += 1  # an edit the evidence checks do not see: only the signature
    doc = _rehash_rig(doc)
    doc["signature"] = honest["signature"]
    path = tmp_path / "R1.json"
    path.write_text(json.dumps(doc))
    monkeypatch.delenv("CALIBCTL_SIGNING_KEY")
    r = invoke("sqlite:///unused.db", "lint", str(path))
    assert r.exit_code == 1 and "does not match its content: it was edited after signing" in _text(r)
    url = _target(source, db_url, tmp_path)  # no key, no trusted keys
    r = invoke(url, "rig", "import", str(path))
    assert r.exit_code == 2 and "does not match its content: it was edited after signing" in _text(r)
    assert _rig_versions(url) == []
    r = invoke(url, "--json", "rig", "import", str(folder / "rig.json"))
    assert r.exit_code == 0, r.output
    got = json.loads(invoke(url, "--json", "rig", "show", "R1").stdout)
    assert got["provenance"]["import_signature"] == f"untrusted key {honest['signature']['key_id']}"


@pytest.mark.parametrize("fmt", ["ros", "opencv", "kalibr", "mrcal"])
def test_single_camera_exports_carry_the_artifacts_signature(keyed, db, tmp_path, fmt, monkeypatch):
    source, trusted, other = keyed
    path = tmp_path / f"CAM0.{fmt}"
    assert invoke(source, "export", "CAM0", "--format", fmt, "-o", str(path)).exit_code == 0
    monkeypatch.delenv("CALIBCTL_SIGNING_KEY")  # the reader holds no key: it trusts only --trusted-keys
    text = path.read_text()
    assert "# calibctl signature ed25519 key_id " in text and "# calibctl file-signature ed25519 " in text
    lint = ("lint", str(path), "--require-signature", "--trusted-keys")
    r = invoke(source, *lint, str(trusted))
    assert r.exit_code == 0, r.output
    r = invoke(source, *lint, str(other))
    assert r.exit_code == 1 and "which is not trusted" in _text(r)
    # a number edited and the file-sha256 line recomputed: the artifact's signature still matches the
    # version the header names; the file's own signature does not match the file
    number = re.search(r"\b(\d{3}\.\d+)", text.split("file-signature", 1)[1]).group(1)
    _reseal(tmp_path, path.name, text.replace(number, f"{float(number) + 1.5!r}", 1))
    r = invoke(source, *lint, str(trusted))
    assert r.exit_code == 1 and "the file has a signature by key" in _text(r)
    r = invoke(source, "lint", str(path))  # no keys asked for: a signature that does not match still fails
    assert r.exit_code == 1 and "does not match its content" in _text(r)
    without = "".join(
        line for line in text.splitlines(keepends=True) if "calibctl file-signature" not in line
    )
    _reseal(tmp_path, path.name, without)  # the file signature removed: only --require-signature asks for it
    assert invoke(source, "lint", str(path)).exit_code == 0
    r = invoke(source, *lint, str(trusted))
    assert r.exit_code == 1 and "the file itself is not signed" in _text(r)
    value = re.search(r"calibctl signature .* value (\S)", text).group(1)
    _reseal(tmp_path, path.name, text.replace(f" value {value}", f" value {'B' if value != 'B' else 'C'}", 1))
    r = invoke(source, *lint, str(trusted))
    assert r.exit_code == 1 and "does not match its content" in _text(r)
    unsigned = tmp_path / f"unsigned.{fmt}"
    assert invoke(db, "export", "CAM0", "--format", fmt, "-o", str(unsigned)).exit_code == 0
    r = invoke(db, "lint", str(unsigned), "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 1 and "carries no signature line" in _text(r)
    assert "from the store that holds it writes the artifact's signature" in _text(r)


def test_a_rig_camera_info_whose_header_names_another_camera_is_refused(signed, tmp_path):
    source, _, _ = signed
    out = tmp_path / "ros"
    assert invoke(source, "rig", "export", "R1", "--format", "ros", "-o", str(out)).exit_code == 0
    assert invoke(source, "lint", str(out / "cam1.yaml")).exit_code == 0
    text = (out / "cam1.yaml").read_text()
    _reseal(out, "cam1.yaml", text.replace("camera_name: cam1", "camera_name: cam0", 1))
    r = invoke(source, "lint", str(out / "cam1.yaml"))
    assert (
        r.exit_code == 1
        and "its header names CAM1@1 (frame cam1_optical_frame) but its camera_name is cam0" in _text(r)
    )


def test_frame_names_swapped_consistently_are_caught_only_by_the_manifests_own_signature(
    keyed, tmp_path, monkeypatch
):
    """The frame names and roles are the exporter's choice (`--frame`), which the rig signature does not
    cover: every file derived again with CAM0 and CAM1's frames swapped is consistent with rig.json; only the
    manifest's own signature refuses it."""
    from calibctl.artifacts.rig import RigCalibration
    from calibctl.workflows.exports import bundle, rig_bundle

    source, trusted, _ = keyed
    folder = _bundle(source, tmp_path / "bundle")
    assert _lint(folder, trusted).exit_code == 0
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["frames"] = {"CAM0": "cam1_optical_frame", "CAM1": "cam0_optical_frame"}
    cal = RigCalibration.model_validate(json.loads((folder / "rig.json").read_text()))
    files, derived = rig_bundle.bundle_files(rig_bundle.derive_from_manifest(cal, manifest))
    for name, body in files.items():
        (folder / name).write_text(body)
    listed = [
        {"path": n, "sha256": bundle.sha256_of(b.encode()), "bytes": len(b.encode())}
        for n, b in files.items()
    ]
    kept = {k: manifest[k] for k in ("format", "schema_version", "calibctl_version", "manifest_signature")}
    (folder / "manifest.json").write_text(json.dumps({**derived, **kept, "files": listed}))
    plain = invoke(
        "sqlite:///unused.db", "lint", str(folder / "manifest.json")
    )  # consistent but for the seal
    assert plain.exit_code == 1 and "the manifest has a signature by key" in _text(plain)
    assert "it was edited after signing" in _text(plain)  # told without trusted keys: the key travels along
    r = _lint(folder, trusted)
    assert (
        r.exit_code == 1
        and "the manifest has a signature by key" in _text(r)
        and "does not match" in _text(r)
    )
    renamed = _bundle(source, tmp_path / "renamed", "--frame", "CAM0=left_optical_frame")
    assert _lint(renamed, trusted).exit_code == 0  # a choice the key holder made and signed
    monkeypatch.delenv("CALIBCTL_SIGNING_KEY")
    unsigned = _bundle(source, tmp_path / "unsigned")  # the rig is signed, the manifest is not
    r = _lint(unsigned, trusted)
    assert r.exit_code == 1 and "the manifest is not signed" in _text(r)


def test_a_file_the_manifest_does_not_list_is_named_by_lint_and_import(signed, sqlite_url, tmp_path):
    source, trusted, _ = signed
    folder = _bundle(source, tmp_path / "bundle")
    (folder / "notes.txt").write_text("a technician's notes")
    r = invoke("sqlite:///unused.db", "lint", str(folder / "manifest.json"))
    assert r.exit_code == 0, r.output  # a warning: every file the robot needs is as signed
    assert f"{folder} holds notes.txt, which its manifest.json does not list" in _text(r)
    url = _target(source, sqlite_url, tmp_path)
    r = invoke(url, "rig", "import", str(folder), "--trusted-keys", str(trusted))
    assert r.exit_code == 0 and "holds notes.txt, which its manifest.json does not list" in _text(r), r.output
    assert _rig_versions(url) == [(1, "accepted")]


def test_a_listed_file_turned_into_a_symlink_out_of_the_bundle_is_refused_by_import(
    signed, sqlite_url, tmp_path
):
    source, _, _ = signed
    folder = _bundle(source, tmp_path / "bundle")
    outside = tmp_path / "outside.yaml"
    outside.write_bytes((folder / "cam1.yaml").read_bytes())  # the same bytes: only the link is wrong
    (folder / "cam1.yaml").unlink()
    (folder / "cam1.yaml").symlink_to(outside)
    url = _target(source, sqlite_url, tmp_path)
    r = invoke(url, "rig", "import", str(folder))
    assert r.exit_code == 1 and f"{folder / 'cam1.yaml'} is a symlink" in _text(r), r.output
    assert "nothing was stored" in _text(r) and _rig_versions(url) == []


@pytest.mark.parametrize("fmt", ["kalibr", "tf"])
def test_a_rig_export_is_signed_as_a_file_and_an_edited_number_is_refused(keyed, tmp_path, fmt, monkeypatch):
    source, trusted, _ = keyed
    path = tmp_path / f"rig.{fmt}.yaml"
    assert invoke(source, "rig", "export", "R1", "--format", fmt, "-o", str(path)).exit_code == 0
    monkeypatch.delenv("CALIBCTL_SIGNING_KEY")
    text = path.read_text()
    assert "# calibctl rig-signature ed25519 " in text and "# calibctl file-signature ed25519 " in text
    lint = ("lint", str(path), "--require-signature", "--trusted-keys", str(trusted))
    assert invoke(source, *lint).exit_code == 0
    number = re.search(r"(-?\d\.\d{4,})", text.split("file-signature", 1)[1]).group(1)
    _reseal(tmp_path, path.name, text.replace(number, f"{float(number) + 0.01!r}", 1))
    r = invoke(source, *lint)
    assert r.exit_code == 1 and "the file has a signature by key" in _text(r)
