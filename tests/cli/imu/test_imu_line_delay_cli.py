"""`calibctl imu synth --line-delay-us` and `imu solve --line-delay`: the rolling-shutter line delay
rendered is read back within its one-sigma."""

from __future__ import annotations

import json

from tests.workflows.imu.imu_data import CAM, cli, make_store


def test_a_rendered_line_delay_is_read_back_within_its_sigma(tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    rec = tmp_path / "rec"
    r = cli(url, "imu", "synth", str(rec), "--serial", CAM, "--duration-s", "3", "--line-delay-us", "30")
    assert r.exit_code == 0, r.output
    assert json.loads((rec / "truth.json").read_text())["line_delay_s"] == 30e-6
    noise = ["--noise", str(rec / "imu.yaml"), "--folds", "0", "--json"]
    r = cli(url, "imu", "solve", str(rec), "--serial", CAM, "--line-delay", *noise)
    assert r.exit_code == 0, r.output
    e = json.loads(r.stdout)["estimate"]
    assert 0 < e["sigma_line_delay_us"] < 3.0
    assert abs(e["line_delay_us"] - 30.0) < 4 * e["sigma_line_delay_us"]
