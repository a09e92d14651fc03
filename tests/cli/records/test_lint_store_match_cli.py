"""`calibctl --db URL lint FILE`: a camera export's numbers against the stored version its header names.

Someone with a text editor deletes the `file-sha256` line and edits a number: without a store lint can
only warn; with one, the file is not the version it names and lint fails (exit 1)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

runner = CliRunner()
WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


def _lint(url: str, path: Path) -> tuple[int, list[dict]]:
    done = runner.invoke(app, ["--db", url, "lint", str(path), "--json"])
    return done.exit_code, json.loads(done.stdout)["results"][0]["findings"]


@pytest.fixture
def store_url(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_artifact(calibration(fx=812.25), activate=True, **WHO)
    return sqlite_url


def _exported(url: str, fmt: str, out: Path) -> str:
    done = runner.invoke(app, ["--db", url, "export", "CAM-0001", "--format", fmt, "-o", str(out)])
    assert done.exit_code == 0, done.output
    return out.read_text()


def _unhashed(text: str) -> str:
    return "".join(line for line in text.splitlines(keepends=True) if "calibctl file-sha256" not in line)


@pytest.mark.parametrize(("fmt", "name"), [("ros", "cam.yaml"), ("opencv", "cam.yml")])
def test_an_edited_number_under_a_header_without_its_hash_fails_against_the_store(
    store_url, tmp_path, fmt, name
):
    out = tmp_path / name
    text = _exported(store_url, fmt, out)
    assert "812.25" in text  # fx, printed alike by both writers
    out.write_text(_unhashed(text).replace("812.25", "822.25", 1))
    code, found = _lint(store_url, out)
    assert code == 1
    match = [f for f in found if f["rule"] == "store-match"]
    assert match and match[0]["severity"] == "error" and "fx file" in match[0]["message"]
    # the same file unedited, hash line gone: the numbers are the stored version's, nothing to say
    out.write_text(_unhashed(text))
    code, found = _lint(store_url, out)
    assert code == 0 and not [f for f in found if f["rule"] == "store-match"]


def test_a_header_naming_another_stores_version_fails(store_url, sqlite_url, tmp_path):
    out = tmp_path / "cam.yaml"
    _exported(store_url, "ros", out)
    other = f"sqlite:///{tmp_path / 'other.db'}"
    with Store.open(other) as store:  # the same serial@version, solved elsewhere
        store.add_artifact(calibration(fx=901.0), activate=True, **WHO)
    code, found = _lint(other, out)
    assert code == 1
    assert any(f["rule"] == "store-match" and "another store's calibration" in f["message"] for f in found)


def test_a_version_the_store_does_not_hold_is_a_warning(store_url, tmp_path):
    out = tmp_path / "cam.yaml"
    _exported(store_url, "ros", out)
    empty = f"sqlite:///{tmp_path / 'empty.db'}"
    with Store.open(empty):
        pass
    code, found = _lint(empty, out)
    assert code == 0
    assert any(f["rule"] == "store-match" and f["severity"] == "warning" for f in found)
