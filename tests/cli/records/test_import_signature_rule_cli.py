"""A store that requires signatures (it has keys) never makes an unsigned or untrusted import active unless
``--activate`` says so, and records how the source was signed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.store.repository import Store
from calibctl.workflows.store_admin.keys import signer_of
from tests.artifacts.factories import calibration

SERIAL = "CAM-S"
HELD = "imported unsigned, not active (this store requires signatures; --activate to override)"
runner = CliRunner()


def run(*args: str, env: dict[str, str] | None = None):
    return runner.invoke(app, list(args), env={"CALIBCTL_OPERATOR": "qa", **(env or {})})


@pytest.fixture
def world(tmp_path: Path) -> dict[str, Path]:
    """A source station's key and export, that export unsigned, a stranger's export, a trusted-keys folder
    holding only the source station's public key, and the target store's own key."""
    paths = {name: tmp_path / f"{name}.pem" for name in ("source_key", "stranger_key", "own_key")}
    paths["trusted"] = tmp_path / "trusted"
    paths["trusted"].mkdir()
    for name in ("source_key", "stranger_key", "own_key"):
        assert run("keys", "init", "--key", str(paths[name])).exit_code == 0
    assert (
        run(
            "keys",
            "export-public",
            "--key",
            str(paths["source_key"]),
            "-o",
            str(paths["trusted"] / "source.pem"),
        ).exit_code
        == 0
    )
    for name, key in (("signed", "source_key"), ("stranger", "stranger_key")):
        url = f"sqlite:///{tmp_path / (name + '.db')}"
        with Store.open(
            url, signer=signer_of(load_settings(env={"CALIBCTL_SIGNING_KEY": str(paths[key])}))
        ) as store:
            store.add_artifact(
                calibration(serial=SERIAL), activate=True, reason="solved", actor="qa", station="st1"
            )
        paths[name] = tmp_path / f"{name}.json"
        assert run("--db", url, "export", SERIAL, "-o", str(paths[name])).exit_code == 0
    data = json.loads(paths["signed"].read_text())
    del data["signature"]
    paths["unsigned"] = tmp_path / "unsigned.json"
    paths["unsigned"].write_text(json.dumps(data))
    paths["target"] = tmp_path / "target.db"
    return paths


def _keyed(world: dict[str, Path]) -> dict[str, str]:
    return {"CALIBCTL_TRUSTED_KEYS": str(world["trusted"])}


def _stored(world: dict[str, Path]):
    with Store.open(f"sqlite:///{world['target']}") as store:
        (art,) = store.list_artifacts(SERIAL)
        return art, store.active_version(SERIAL), store.events(SERIAL)


def test_signed_by_a_trusted_key_is_active_and_marked(world):
    result = run("--db", str(world["target"]), "import", str(world["signed"]), env=_keyed(world))
    assert result.exit_code == 0, result.output
    assert "active;" in result.stdout and "not active" not in result.stdout
    art, active, events = _stored(world)
    assert active == 1 and len(events) == 1
    assert (
        art.provenance.import_signature
        == f"trusted key {json.loads(world['signed'].read_text())['signature']['key_id']}"
    )


@pytest.mark.parametrize("source", ["unsigned", "stranger"])
def test_unsigned_or_untrusted_into_a_store_with_keys_is_stored_marked_and_not_active(world, source):
    result = run("--db", str(world["target"]), "import", str(world[source]), "--json", env=_keyed(world))
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["active"] is False and doc["artifact"]["status"] == "accepted"
    art, active, events = _stored(world)
    assert active is None and events == []  # nothing activated, no event written
    if source == "unsigned":
        assert doc["held_back"] == HELD and art.provenance.import_signature == "unsigned"
    else:
        assert doc["held_back"].startswith("imported signed by a key this store does not trust (")
        assert art.provenance.import_signature.startswith("untrusted key ")
    plain = run("--db", str(world["target"]), "import", str(world[source]))  # the same content: a no-op
    assert plain.exit_code == 0 and f"already stored as {SERIAL}@1" in plain.stdout


def test_the_held_back_line_is_printed(world):
    result = run("--db", str(world["target"]), "import", str(world["unsigned"]), env=_keyed(world))
    assert result.exit_code == 0 and HELD in result.stdout and "not active" in result.stdout


def test_a_signing_key_alone_makes_the_store_require_signatures(world):
    result = run(
        "--db",
        str(world["target"]),
        "import",
        str(world["unsigned"]),
        env={"CALIBCTL_SIGNING_KEY": str(world["own_key"])},
    )
    assert result.exit_code == 0 and HELD in result.stdout
    art, active, _ = _stored(world)
    assert (
        active is None and art.signature is not None
    )  # this store signed its version; the mark says the source was not
    assert art.provenance.import_signature == "unsigned"


def test_explicit_activate_overrides_and_the_event_records_it(world):
    result = run(
        "--db", str(world["target"]), "import", str(world["unsigned"]), "--activate", env=_keyed(world)
    )
    assert result.exit_code == 0, result.output
    assert "active;" in result.stdout and HELD not in result.stdout
    art, active, (event,) = _stored(world)
    assert active == 1
    assert (
        event.reason
        == f"imported {SERIAL}@1 (unsigned; activated with --activate although this store requires "
        "signatures)"
    )


def test_a_store_without_keys_activates_an_unsigned_import_as_before(world):
    result = run("--db", str(world["target"]), "import", str(world["unsigned"]))
    assert result.exit_code == 0 and HELD not in result.stdout
    art, active, (event,) = _stored(world)
    assert (
        active == 1
        and event.reason == f"imported {SERIAL}@1"
        and art.provenance.import_signature == "unsigned"
    )


def test_no_activate_keeps_a_trusted_import_inactive_without_the_signature_line(world):
    result = run(
        "--db", str(world["target"]), "import", str(world["signed"]), "--no-activate", env=_keyed(world)
    )
    assert (
        result.exit_code == 0 and "not active" in result.stdout and "requires signatures" not in result.stdout
    )
    assert _stored(world)[1] is None


def test_a_rejected_unsigned_import_is_exit_1_and_never_active_even_with_activate(world, tmp_path):
    data = json.loads(world["unsigned"].read_text())
    data["stdev"]["sigma"] = {"fx": 9.0, "fy": 9.0}
    from calibctl.artifacts.calibration import CalibrationArtifact

    forged = tmp_path / "forged.json"
    forged.write_text(json.dumps(CalibrationArtifact.model_validate(data).sealed().model_dump(mode="json")))
    for extra in ([], ["--activate"]):
        result = run("--db", str(world["target"]), "import", str(forged), *extra, env=_keyed(world))
        assert result.exit_code == 1, result.output
        assert "rejected by this store's lint" in result.stdout and "requires signatures" not in result.stdout
    art, active, events = _stored(world)
    assert art.status == "rejected" and active is None and events == []
