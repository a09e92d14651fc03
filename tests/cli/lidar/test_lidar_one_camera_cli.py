"""One camera and a LiDAR stored as a versioned rig edge: `rig add` with one camera, `rig solve` pins it,
`lidar solve --rig` stores the edge lidar -> camera as the next active version, which lint passes and the
tf export carries with the solved T."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from calibctl.store.repository import Store
from calibctl.workflows.lidar.lidar_synth import run_lidar_synth
from tests.cli.lidar.test_lidar_rig_cli import CAM, CAM_FRAME, WHO, _cli, _lens, _solve_args
from tests.workflows.handeye.test_rig_handeye import _tf

MONO = "MONO-1"


def test_one_camera_and_a_lidar_are_stored_as_the_rigs_next_version(tmp_path: Path) -> None:
    run_lidar_synth(tmp_path / "good", 10, 1, 0.0, False, False)
    url = f"sqlite:///{tmp_path / 'calibctl.db'}"
    with Store.open(url) as store:
        store.add_artifact(_lens(CAM), activate=True, **WHO)
    for args in (("rig", "add", MONO, "--camera", CAM, "--frame", "lidar"), ("rig", "solve", MONO)):
        assert _cli(url, *args).exit_code == 0
    args = _solve_args(tmp_path / "good", "--serial", CAM, "--rig", MONO, "--lidar-frame", "lidar", "--json")
    done = _cli(url, *args)
    assert done.exit_code == 0, done.output
    result = json.loads(done.stdout)
    assert (result["stored"]["version"], result["stored"]["status"], result["stored"]["active"]) == (
        2,
        "accepted",
        True,
    )
    history = json.loads(_cli(url, "rig", "history", MONO, "--json").stdout)
    assert history["active_version"] == 2
    assert history["versions"][1]["lidar"] == [{"edge": f"lidar:{CAM}", "status": "accepted"}]
    assert _cli(url, "rig", "lint", MONO).exit_code == 0
    tf = _tf(_cli(url, "rig", "export", MONO, "--format", "tf").stdout)
    assert set(tf) == {("lidar", CAM_FRAME)}
    assert np.allclose(tf[("lidar", CAM_FRAME)], result["transform"]["matrix"], atol=1e-8)
