"""A store-free `lidar solve -o` result is hashed (and signed with a key) and `lint FILE` checks it. The solve
itself is the precision test's fixed outcome: what is tested is the file, not the fit."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.workflows.exports import sealed_result
from calibctl.workflows.lidar import lidar_run
from tests.workflows.edges.test_lidar_precision import _outcome

SOLVE = ["lidar", "solve", "--cols", "5", "--rows", "7", "--square-mm", "95", "--backing-mm", "610,850"]


def run(*args: str, env: dict[str, str] | None = None):
    return CliRunner().invoke(app, list(args), env=env, terminal_width=200)


@pytest.fixture
def solved(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """``solve(out, key)``: `lidar solve -o out` (with ``key`` configured, or none) on a fixed outcome."""
    monkeypatch.setattr(lidar_run, "run_lidar_solve", lambda settings, req: _outcome())
    (tmp_path / "i").mkdir()
    (tmp_path / "s").mkdir()
    cam = tmp_path / "cam.yaml"
    cam.write_text("width: 640\n")

    def solve(out: Path, key: Path | None = None) -> Path:
        where = ["--images", str(tmp_path / "i"), "--scans", str(tmp_path / "s"), "--camera-info", str(cam)]
        env = {"CALIBCTL_SIGNING_KEY": str(key)} if key else None
        r = run(*SOLVE, *where, "--box", "0,0,0,1,1,1", "-o", str(out), "--json", env=env)
        assert r.exit_code == 0, r.output
        return out

    return solve


@pytest.fixture
def key(tmp_path: Path) -> tuple[Path, Path]:
    """A signing key and a trusted-keys folder holding its public half."""
    k, trusted = tmp_path / "k.pem", tmp_path / "trusted"
    trusted.mkdir()
    assert run("keys", "init", "--key", str(k)).exit_code == 0
    assert run("keys", "export-public", "--key", str(k), "-o", str(trusted / "k.pem")).exit_code == 0
    return k, trusted


def _lint(path: Path, *args: str):
    r = run("lint", str(path), "--format", "json", *args)
    messages = [f["message"] for x in json.loads(r.stdout)["results"] for f in x["findings"]]
    return r.exit_code, messages


def test_a_signed_result_lints_clean_and_an_edit_is_refused(solved, key, tmp_path: Path):
    k, trusted = key
    path = solved(tmp_path / "result.json", k)
    doc = json.loads(path.read_text())
    assert doc["kind"] == "lidar-result" and doc["signature"]["public_key"]
    assert _lint(path) == (0, [])
    assert _lint(path, "--require-signature", "--trusted-keys", str(trusted)) == (0, [])
    doc["transform"]["matrix"][0][3] += 0.01  # 10 mm, and every number derived from it
    doc["transform"]["translation_m"][0] += 0.01
    doc["transform"]["T_cam_lidar"][0][3] -= 0.01
    path.write_text(json.dumps(doc))
    code, messages = _lint(path)
    assert code == 1 and messages == [f"{path} was edited (its content hash does not match)"]
    doc["content_sha256"] = sealed_result.content_sha256(doc)  # re-hashed, the signature kept
    path.write_text(json.dumps(doc))
    code, messages = _lint(path)  # no trusted keys: the signature carries its public key
    assert code == 1 and len(messages) == 1
    assert "does not match its content: it was edited after signing" in messages[0]


def test_an_unsigned_result_passes_unless_a_signature_is_required(solved, key, tmp_path: Path):
    _, trusted = key
    path = solved(tmp_path / "result.json")
    assert "signature" not in json.loads(path.read_text())
    assert _lint(path) == (0, [])
    code, messages = _lint(path, "--require-signature", "--trusted-keys", str(trusted))
    assert code == 1 and messages == [f"{path} is not signed"]


def test_a_rehashed_result_whose_numbers_disagree_and_an_unhashed_one_are_refused(solved, tmp_path: Path):
    path = solved(tmp_path / "result.json")
    doc = json.loads(path.read_text())
    doc["transform"]["translation_m"][0] += 0.01  # the matrix left as it was
    doc["content_sha256"] = sealed_result.content_sha256(doc)
    path.write_text(json.dumps(doc))
    code, messages = _lint(path)
    assert code == 1 and messages == [f"{path}: T_cam_lidar and translation_m are not transform.matrix's"]
    for field in ("kind", "content_sha256"):
        doc.pop(field)
    path.write_text(json.dumps(doc))
    code, messages = _lint(path)
    assert code == 1 and messages == [f"{path} carries no content hash (written before results were sealed)"]
