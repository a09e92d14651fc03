"""`calibctl imu solve --bias-walk`: the biases solved as random walks reach the estimator (their
constants leave the state list), the result says so, and the render's truth is read back."""

from __future__ import annotations

import json

import numpy as np

from tests.workflows.imu.imu_data import CAM, TD_S, cli, make_store, truth


def test_bias_walk_solves_the_biases_as_random_walks(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    noise = ["--noise", str(recording / "imu.yaml"), "--folds", "0", "--json"]
    r = cli(url, "imu", "solve", str(recording), "--serial", CAM, "--bias-walk", *noise)
    assert r.exit_code == 0, r.output
    e = json.loads(r.stdout)["estimate"]
    assert e["bias_walk"] is True
    assert "bg_x" not in e["sigma_inflation"] and "rot_x" in e["sigma_inflation"]
    assert abs(e["td_ms"] - TD_S * 1e3) < 5 * e["sigma_td_ms"]
    t = truth(recording)
    assert np.allclose(np.array(e["T_cam_imu"])[:3, :3], np.array(t["T_cam_imu"])[:3, :3], atol=2e-3)
