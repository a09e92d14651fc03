"""keys init / export-public, signed exports, and import / lint / db verify that require a trusted
signature."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.store.repository import Store
from calibctl.workflows.store_admin.keys import signer_of
from tests.artifacts.factories import calibration, measured_board_args

runner = CliRunner()
WHO = {"actor": "qa", "station": "st1"}


def run(*args: str, env: dict[str, str] | None = None):
    return runner.invoke(app, list(args), env=env)


@pytest.fixture
def keys(tmp_path: Path) -> dict[str, Path]:
    """A station key, its public key in a trusted folder, and a stranger's key in another folder."""
    paths = {
        "key": tmp_path / "station.pem",
        "trusted": tmp_path / "trusted",
        "stranger": tmp_path / "stranger.pem",
        "untrusted": tmp_path / "untrusted",
    }
    paths["trusted"].mkdir()
    paths["untrusted"].mkdir()
    assert run("keys", "init", "--key", str(paths["key"])).exit_code == 0
    assert (
        run(
            "keys", "export-public", "--key", str(paths["key"]), "-o", str(paths["trusted"] / "station.pem")
        ).exit_code
        == 0
    )
    assert run("keys", "init", "--key", str(paths["stranger"])).exit_code == 0
    assert (
        run(
            "keys", "export-public", "--key", str(paths["stranger"]), "-o", str(paths["untrusted"] / "s.pem")
        ).exit_code
        == 0
    )
    return paths


def _signed_export(url: str, key: Path, out: Path) -> Path:
    signer = signer_of(load_settings(env={"CALIBCTL_SIGNING_KEY": str(key)}))
    with Store.open(url, signer=signer) as store:
        store.add_artifact(calibration(serial="CAM-S"), activate=True, reason="solved", **WHO)
    assert run("--db", url, "export", "CAM-S", "-o", str(out)).exit_code == 0
    return out


def test_init_writes_a_0600_key_and_never_overwrites_it(tmp_path: Path):
    key = tmp_path / "k.pem"
    first = run("keys", "init", "--key", str(key), "--json")
    assert first.exit_code == 0, first.output
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    again = run("keys", "init", "--key", str(key))
    assert again.exit_code == 2 and "exists" in again.stderr and "--force" in again.stderr
    public = run("keys", "export-public", "--key", str(key))
    assert public.stdout.startswith("-----BEGIN PUBLIC KEY-----")
    assert json.loads(first.stdout)["public_pem"] == public.stdout


def test_a_missing_or_loose_key_file_is_exit_2_and_nothing_is_written(sqlite_url: str, tmp_path: Path):
    missing = run(
        "--db",
        sqlite_url,
        *measured_board_args("A17"),
        env={"CALIBCTL_SIGNING_KEY": str(tmp_path / "nope.pem")},
    )
    assert missing.exit_code == 2 and "nope.pem does not exist" in missing.stderr
    assert not Path(sqlite_url.removeprefix("sqlite:///")).exists()
    loose = tmp_path / "loose.pem"
    assert run("keys", "init", "--key", str(loose)).exit_code == 0
    loose.chmod(0o644)
    result = run("keys", "export-public", "--key", str(loose))
    assert result.exit_code == 2 and "readable by others" in result.stderr and "chmod 600" in result.stderr
    assert run("keys", "export-public").exit_code == 2  # no key configured at all


def test_export_carries_the_signature_and_import_requires_a_trusted_one(
    keys: dict[str, Path], tmp_path: Path
):
    source = f"sqlite:///{tmp_path / 'source.db'}"
    target = f"sqlite:///{tmp_path / 'target.db'}"
    exported = _signed_export(source, keys["key"], tmp_path / "cam.json")
    seal = json.loads(exported.read_text())["signature"]
    assert seal["algorithm"] == "ed25519" and len(seal["key_id"]) == 64

    untrusted = run(
        "--db",
        target,
        "import",
        str(exported),
        "--require-signature",
        "--trusted-keys",
        str(keys["untrusted"]),
    )
    assert untrusted.exit_code == 2 and "which is not trusted" in untrusted.stderr
    assert not (tmp_path / "target.db").exists()  # nothing written

    unsigned = tmp_path / "unsigned.json"
    data = json.loads(exported.read_text())
    del data["signature"]
    unsigned.write_text(json.dumps(data))
    refused = run(
        "--db", target, "import", str(unsigned), "--require-signature", "--trusted-keys", str(keys["trusted"])
    )
    assert refused.exit_code == 2 and "is not signed" in refused.stderr

    ok = run(
        "--db", target, "import", str(exported), "--require-signature", "--trusted-keys", str(keys["trusted"])
    )
    assert ok.exit_code == 0, ok.output


def test_a_signature_moved_to_other_content_is_refused_even_without_require(
    keys: dict[str, Path], tmp_path: Path
):
    exported = _signed_export(f"sqlite:///{tmp_path / 's.db'}", keys["key"], tmp_path / "cam.json")
    other = json.loads(
        _signed_export(f"sqlite:///{tmp_path / 'o.db'}", keys["key"], tmp_path / "o.json").read_text()
    )
    data = json.loads(exported.read_text())
    data["signature"] = {**other["signature"], "record_sha256": "0" * 64}
    forged = tmp_path / "forged.json"
    forged.write_text(json.dumps(data))
    result = run(
        "--db",
        f"sqlite:///{tmp_path / 't.db'}",
        "import",
        str(forged),
        "--trusted-keys",
        str(keys["trusted"]),
    )
    assert result.exit_code == 2 and "does not match its content" in result.stderr


def test_lint_require_signature(keys: dict[str, Path], tmp_path: Path):
    url = f"sqlite:///{tmp_path / 's.db'}"
    exported = _signed_export(url, keys["key"], tmp_path / "cam.json")
    ros = tmp_path / "cam.yaml"
    # exported where the key is configured: the file itself is signed too (`lint --require-signature` asks)
    keyed = {"CALIBCTL_SIGNING_KEY": str(keys["key"])}
    assert run("--db", url, "export", "CAM-S", "--format", "ros", "-o", str(ros), env=keyed).exit_code == 0

    def signature_findings(*args: str) -> tuple[int, list[str]]:
        result = run("--db", url, "lint", *args, "--require-signature", "--format", "json")
        report = json.loads(result.stdout)
        return result.exit_code, [
            f["message"] for r in report["results"] for f in r["findings"] if f["rule"] == "signature"
        ]

    assert signature_findings(str(exported), "--trusted-keys", str(keys["trusted"])) == (0, [])
    code, messages = signature_findings(str(exported), "--trusted-keys", str(keys["untrusted"]))
    assert code == 1 and "which is not trusted" in messages[0]
    # the ROS export carries the artifact's signature line: checked like the JSON's
    assert signature_findings(str(ros), "--trusted-keys", str(keys["trusted"])) == (0, [])
    code, messages = signature_findings(str(ros), "--trusted-keys", str(keys["untrusted"]))
    assert code == 1 and "which is not trusted" in messages[0]
    assert signature_findings("--all", "--trusted-keys", str(keys["trusted"])) == (0, [])
    none = run("lint", str(exported), "--require-signature")
    assert none.exit_code == 2 and "needs trusted keys" in none.stderr


def test_db_verify_with_trusted_keys_and_head(keys: dict[str, Path], tmp_path: Path):
    url = f"sqlite:///{tmp_path / 's.db'}"
    _signed_export(url, keys["key"], tmp_path / "cam.json")
    result = run(
        "--db", url, "db", "verify", "--trusted-keys", str(keys["trusted"]), "--require-signature", "--head"
    )
    assert result.exit_code == 0, result.output
    assert "signatures: 2 checked against 1 trusted key(s); 0 unsigned record(s)" in result.stdout
    head = result.stdout.split("head ")[-1].strip()
    resumed = run("--db", url, "db", "verify", "--since", head, "--json")
    assert resumed.exit_code == 0 and json.loads(resumed.stdout)["records_checked"] == 0
    stranger = run("--db", url, "db", "verify", "--trusted-keys", str(keys["untrusted"]))
    assert stranger.exit_code == 1 and "which is not trusted" in stranger.stdout
    bad = run("--db", url, "db", "verify", "--since", "HEAD")
    assert bad.exit_code == 2 and "is not a chain head" in bad.stderr


def test_import_require_signature_without_trusted_keys_is_exit_2(keys: dict[str, Path], tmp_path: Path):
    exported = _signed_export(f"sqlite:///{tmp_path / 's.db'}", keys["key"], tmp_path / "cam.json")
    result = run("--db", f"sqlite:///{tmp_path / 't.db'}", "import", str(exported), "--require-signature")
    assert result.exit_code == 2 and "needs trusted keys" in result.stderr
    assert not (tmp_path / "t.db").exists()


def test_rig_rollback_through_the_cli_is_signed_with_the_station_key(sqlite_url: str, keys: dict[str, Path]):
    from tests.store.rig_documents import RIG, rig_calibration, rig_definition

    env = {"CALIBCTL_SIGNING_KEY": str(keys["key"])}
    with Store.open(sqlite_url, signer=signer_of(load_settings(env=env))) as store:
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, reason="rig solve", **WHO)
        store.add_rig_calibration(rig_calibration(baseline_m=0.076), activate=True, reason="rig solve", **WHO)
    rolled = run("--db", sqlite_url, "rig", "rollback", RIG, "--to", "1", "--reason", "bent mount", env=env)
    assert rolled.exit_code == 0, rolled.output
    checked = run(
        "--db",
        sqlite_url,
        "db",
        "verify",
        "--require-signature",
        "--trusted-keys",
        str(keys["trusted"]),
        "--json",
        env=env,
    )
    assert checked.exit_code == 0, checked.output
    report = json.loads(checked.stdout)
    assert (
        report["unsigned"] == 0 and report["signatures_checked"] == 2 + 3 + 1
    )  # rig versions, rig events, definition


def _keyed_export(url: str, key: Path, out: Path, *args: str) -> Path:
    """A signed store's export made with its key configured: the signature carries the public key."""
    _signed_export(url, key, out)
    assert run("--db", url, "export", "CAM-S", "-o", str(out), "--force", *args, env=_KEY(key)).exit_code == 0
    return out


def _KEY(key: Path) -> dict[str, str]:
    return {"CALIBCTL_SIGNING_KEY": str(key)}


def _rehashed(data: dict) -> dict:
    """What a forger without the key does after an edit: the content hash recomputed, the signature kept."""
    from calibctl.artifacts.calibration import CalibrationArtifact

    data["content_sha256"] = CalibrationArtifact.model_validate(data).computed_sha256()
    return data


def test_a_signature_that_does_not_match_is_refused_in_a_keyless_store(
    keys: dict[str, Path], db_url: str, tmp_path: Path
):
    exported = _keyed_export(f"sqlite:///{tmp_path / 's.db'}", keys["key"], tmp_path / "cam.json")
    honest = json.loads(exported.read_text())
    assert honest["signature"]["public_key"]  # the key travels with the signature
    forged = tmp_path / "forged.json"
    data = json.loads(exported.read_text())
    data["camera_matrix"][0][0] += 1.0
    forged.write_text(json.dumps(_rehashed(data)))
    lint = run("lint", str(forged), "--format", "json")  # no key, no trusted keys, not required
    messages = [f["message"] for r in json.loads(lint.stdout)["results"] for f in r["findings"]]
    assert lint.exit_code == 1
    assert any("does not match its content: it was edited after signing" in m for m in messages)
    result = run("--db", db_url, "import", str(forged))  # a store with no keys at all
    assert result.exit_code == 2, result.output
    assert "forged.json (CAM-S@1) has a signature by key" in result.stderr
    assert "does not match its content: it was edited after signing" in result.stderr
    with Store.open(db_url) as store:
        assert store.serials() == []  # nothing stored
    assert run("lint", str(exported)).exit_code == 0  # the honest file: a stranger's valid signature
    ok = run("--db", db_url, "--json", "import", str(exported))
    assert ok.exit_code == 0, ok.output
    with Store.open(db_url) as store:
        mark = store.get_artifact("CAM-S", None).provenance.import_signature
    assert mark == f"untrusted key {honest['signature']['key_id']}"


def test_a_carried_public_key_that_is_not_the_signers_is_refused(keys: dict[str, Path], tmp_path: Path):
    exported = _keyed_export(f"sqlite:///{tmp_path / 's.db'}", keys["key"], tmp_path / "cam.json")
    stranger = _keyed_export(f"sqlite:///{tmp_path / 'o.db'}", keys["stranger"], tmp_path / "o.json")
    data = json.loads(exported.read_text())
    data["signature"]["public_key"] = json.loads(stranger.read_text())["signature"]["public_key"]
    forged = tmp_path / "forged.json"
    forged.write_text(json.dumps(data))
    result = run("--db", f"sqlite:///{tmp_path / 't.db'}", "import", str(forged))
    assert result.exit_code == 2 and "carries a public key that is not key" in result.stderr
    assert not (tmp_path / "t.db").exists()


def test_signature_lines_swapped_between_camera_files_are_refused_without_keys(
    keys: dict[str, Path], tmp_path: Path
):
    """Two cameras' ROS exports from one signed store, each file's signature line moved into the other."""
    url = f"sqlite:///{tmp_path / 's.db'}"
    with Store.open(url, signer=signer_of(load_settings(env=_KEY(keys["key"])))) as store:
        for serial in ("CAM-S", "CAM-T"):
            store.add_artifact(calibration(serial=serial), activate=True, reason="solved", **WHO)
    paths = [tmp_path / f"{serial}.yaml" for serial in ("CAM-S", "CAM-T")]
    for path in paths:
        args = ("--db", url, "export", path.stem, "--format", "ros", "-o", str(path))
        assert run(*args, env=_KEY(keys["key"])).exit_code == 0
    texts = [p.read_text() for p in paths]
    lines = [next(line for line in t.splitlines() if "calibctl signature " in line) for t in texts]
    assert all(run("lint", str(p)).exit_code == 0 for p in paths)
    for path, text, own, other in zip(paths, texts, lines, reversed(lines), strict=True):
        path.write_text(_with_file_sha256(text.replace(own, other)))
        lint = run("lint", str(path))
        assert lint.exit_code == 1 and "it was edited after signing" in lint.output, lint.output


def test_an_old_signature_without_its_public_key_verifies_as_before(keys: dict[str, Path], tmp_path: Path):
    exported = _keyed_export(f"sqlite:///{tmp_path / 's.db'}", keys["key"], tmp_path / "cam.json")
    data = json.loads(exported.read_text())
    del data["signature"]["public_key"]
    exported.write_text(json.dumps(data))
    trusted = ("--require-signature", "--trusted-keys")
    assert run("lint", str(exported), *trusted, str(keys["trusted"])).exit_code == 0
    stranger = run("lint", str(exported), *trusted, str(keys["untrusted"]))
    assert stranger.exit_code == 1 and "which is not trusted" in stranger.output


def _with_file_sha256(text: str) -> str:
    import re

    from calibctl.workflows.exports import trace_header

    digest = trace_header.file_sha256(text)
    return re.sub(r"(calibctl file-sha256 )[0-9a-f]{64}", lambda m: m.group(1) + digest, text)
