"""calibctl demo: the main job end to end (what `make demo` runs)."""

from __future__ import annotations

import yaml
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store

runner = CliRunner()


def test_demo_runs_the_main_job_end_to_end(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, ["demo", "--out", "demo"])
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "rejected (exit 1)" in out and "tilt the board" in out  # the flat set is refused with a hint
    assert "DEMO-CAM-0001@1 (active)  accepted" in out and "lint: clean" in out
    info = yaml.safe_load((tmp_path / "demo" / "camera_info.yaml").read_text())
    assert info["image_width"] == 640 and info["distortion_model"] == "plumb_bob"
    with Store.open(f"sqlite:///{tmp_path / 'demo' / 'calibctl-demo.db'}") as store:
        art = store.get_artifact("DEMO-CAM-0001")
        sessions = store.list_sessions("DEMO-CAM-0001")
    assert sorted(s.status for s in sessions) == ["accepted", "rejected"]
    # the renderer's truth: fx = 800 px; the reported sigma must cover the error
    assert abs(art.camera_matrix[0][0] - 800.0) < 4 * art.stdev.sigma["fx"]
    # a second run recreates its own folder and gives the same numbers (fixed seeds)
    again = runner.invoke(app, ["demo", "--out", "demo"])
    assert again.exit_code == 0, again.output
    with Store.open(f"sqlite:///{tmp_path / 'demo' / 'calibctl-demo.db'}") as store:
        assert store.get_artifact("DEMO-CAM-0001").camera_matrix == art.camera_matrix


def test_demo_refuses_to_wipe_a_folder_it_did_not_make(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "precious").mkdir()
    (tmp_path / "precious" / "notes.txt").write_text("keep")
    result = runner.invoke(app, ["demo", "--out", "precious"])
    assert result.exit_code == 2
    assert "precious exists and was not made by calibctl demo" in result.stderr
    assert (tmp_path / "precious" / "notes.txt").read_text() == "keep"
