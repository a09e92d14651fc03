"""A LiDAR edge for any rig member from the CLI: `lidar synth --serial MEMBER` renders the LiDAR scene
through that member's stored lens, and `lidar solve --rig R1 --serial MEMBER` solves and stores its edge."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from calibctl.errors import UsageError
from calibctl.store.repository import Store
from calibctl.workflows.lidar.lidar_synth import SynthLens
from tests.cli.lidar.test_lidar_cli import BOARD
from tests.cli.rig.test_rig_store_cli import RUNNER, _capture, app
from tests.workflows.rig.test_rig_store_flow import store_members
from tests.workflows.rig_folders_data import rendered_rig


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=200)


@pytest.fixture(scope="module")
def solved(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Rig R1 (CAM0, CAM1 of the 2-camera render, 640 x 480; frame lidar declared), solved once."""
    rig2 = rendered_rig(tmp_path_factory)
    path = tmp_path_factory.mktemp("lidar-member") / "c.db"
    url = store_members(f"sqlite:///{path}", rig2)
    assert (
        invoke(url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1", "--frame", "lidar").exit_code
        == 0
    )
    assert _capture(url, rig2).exit_code == 0
    assert invoke(url, "rig", "solve", "R1").exit_code == 0
    return path


def test_a_member_other_than_the_root_gets_its_lidar_edge_from_the_cli(solved: Path, tmp_path: Path):
    member = "CAM1"  # not the root; the root is the same commands with --serial CAM0
    db = tmp_path / "c.db"
    shutil.copy(solved, db)
    url = f"sqlite:///{db}"
    scene = tmp_path / "scene"
    r = invoke(url, "lidar", "synth", str(scene), "--poses", "12", "--seed", "1", "--serial", member)
    assert r.exit_code == 0 and f"through {member}@1's lens" in r.output, r.output
    with Store.open(url) as store:
        art = store.get_artifact(member, None)
    info = (scene / "camera_info.yaml").read_text()
    assert (
        f"width: {art.image_size[0]}\n" in info and json.dumps(np.ravel(art.camera_matrix).tolist()) in info
    )
    truth = json.loads((scene / "truth.json").read_text())
    assert truth["camera"] == f"{member}@1"
    where = ["--images", str(scene / "images"), "--scans", str(scene / "scans"), "--box", truth["box"]]
    target = ["--serial", member, "--rig", "R1", "--lidar-frame", "lidar", "--json"]
    r = invoke(url, "lidar", "solve", *where, *BOARD, *target)
    assert r.exit_code == 0, r.output
    stored = json.loads(r.stdout)["stored"]
    assert stored["status"] == "accepted" and stored["active"]
    shown = json.loads(invoke(url, "--json", "rig", "show", "R1").stdout)
    assert [(e["parent"], e["child"]) for e in shown["edges"] if e["parent"] == "lidar"] == [
        ("lidar", member)
    ]


def test_a_lens_the_renderer_has_no_model_for_or_an_unknown_camera_is_refused(solved: Path, tmp_path: Path):
    with pytest.raises(UsageError, match="CAM9@2 is a rational calibration"):
        SynthLens.of("CAM9@2", "rational", np.eye(3), [0.1, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0], (640, 480))
    r = invoke(f"sqlite:///{solved}", "lidar", "synth", str(tmp_path / "s"), "--serial", "NOPE")
    assert r.exit_code == 2 and "NOPE" in r.output and not (tmp_path / "s").exists()
