"""docs/content-hash.md's recipe, run word for word (with the independent PyPI rfc8785) on a signed camera
export and on a signed rig export (`rig export --format json` and a bundle's rig.json): the recipe a robot's
developer copies must pass on what calibctl writes."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.signing import create_key
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.rig_documents import RIG, rig_calibration, rig_definition

DOC = Path(__file__).resolve().parents[2] / "docs" / "content-hash.md"
WHO = {"actor": "qa", "station": "st1", "reason": "test"}


def _recipe() -> str:
    return re.search(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.DOTALL).group(1)


def _run_recipe_on(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(path.parent)
    os.replace(path, path.parent / "CAM-0042.json")  # the file name the recipe opens
    exec(compile(_recipe(), str(DOC), "exec"), {})  # its own assert decides


def test_the_recipe_checks_a_signed_camera_export_and_a_signed_rig_export(sqlite_url, tmp_path, monkeypatch):
    with Store.open(sqlite_url, signer=create_key(tmp_path / "k.pem")) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(), activate=True, **WHO)
        store.add_rig(rig_definition())
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
    bundle = ["rig", "export", RIG, "--format", "bundle", "--allow-stale"]
    for args in (["export", "CAM-0001"], ["rig", "export", RIG, "--format", "json", "--allow-stale"], bundle):
        folder = tmp_path / args[0] / args[1] / args[-2]
        folder.mkdir(parents=True)
        out = folder / "export.json"
        target = folder / "bundle" if args is bundle else out
        result = CliRunner().invoke(app, ["--db", sqlite_url, *args, "-o", str(target)])
        assert result.exit_code == 0, result.output
        if args is bundle:
            os.replace(target / "rig.json", out)
        doc = json.loads(out.read_text())
        assert doc["content_hash_algorithm"] == "sha256-rfc8785"
        assert (
            doc["signature"]["algorithm"] == "ed25519"
        )  # signed camera artifact and signed rig version alike
        _run_recipe_on(out, monkeypatch)
        doc["content_sha256"] = "0" * 64
        (folder / "CAM-0042.json").write_text(json.dumps(doc))
        with pytest.raises(AssertionError):  # the recipe can fail: an edited hash does not pass
            exec(compile(_recipe(), str(DOC), "exec"), {})
