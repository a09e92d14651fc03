"""One camera and an IMU stored as a versioned rig edge, on the shared render: `rig add` with one camera,
`rig solve` pins its calibration (no capture, no camera-camera edge), `imu solve --rig` stores the edge as the
next version; history, rollback, rig lint, Kalibr's camchain-imucam (one camera), tf, URDF, the bundle and the
report carry it; re-calibrating the camera makes the edge stale until the rig is solved again."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.workflows.imu.imu_data import CAM, MONO, WHO, cli, copy_db, make_mono_store, make_store
from tests.workflows.urdf_check import loadable_urdf

CAM_FRAME = "cam_0001_optical_frame"


def _yaml_body(text: str) -> dict:
    return yaml.safe_load("\n".join(x for x in text.splitlines() if not x.startswith("#")))


def _history(url: str) -> dict:
    done = cli(url, "rig", "history", MONO, "--json")
    assert done.exit_code == 0, done.output
    return json.loads(done.stdout)


@pytest.fixture(scope="module")
def stored(recording, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """A store whose one-camera rig got the IMU edge (version 2), and `imu solve --json`'s document."""
    db = tmp_path_factory.mktemp("imu-mono") / "mono.db"
    url = make_mono_store(db)
    noise = str(recording / "imu.yaml")
    done = cli(
        url, "imu", "solve", str(recording), "--serial", CAM, "--noise", noise, "--rig", MONO, "--json"
    )
    assert done.exit_code == 0, done.output
    return db, json.loads(done.stdout)


@pytest.fixture
def url(stored, tmp_path: Path) -> str:
    return copy_db(stored[0], tmp_path)


def test_a_one_camera_rig_is_added_and_solved_by_pinning_its_members_calibration(tmp_path) -> None:
    url = make_store(tmp_path / "c.db", other_calibrated=False)
    added = cli(url, "rig", "add", MONO, "--camera", CAM, "--frame", "imu", "--json")
    assert added.exit_code == 0, added.output
    assert (json.loads(added.stdout)["cameras"], json.loads(added.stdout)["root"]) == ([CAM], CAM)
    early = cli(url, "imu", "solve", "unused", "--serial", CAM, "--rig", MONO)  # no version yet: exit 2
    assert early.exit_code == 2 and "Traceback" not in early.output
    assert "no calibration yet" in early.output and "a one-camera rig needs none" in early.output
    solved = cli(url, "rig", "solve", MONO, "--json")
    assert solved.exit_code == 0, solved.output
    doc = json.loads(solved.stdout)
    (member,) = doc["members"]
    shown = json.loads(cli(url, "show", CAM, "--json").stdout)
    assert (member["serial"], member["version"], member["content_sha256"]) == (
        CAM,
        1,
        shown["content_sha256"],
    )
    assert member["camera_matrix"] == shown["camera_matrix"] and not member["refined"]
    assert (doc["status"], doc["edges"], doc["pairs"], doc["loops"]) == ("accepted", [], [], [])
    assert _history(url)["active_version"] == 1


def test_the_imu_edge_is_the_next_version_with_history_rollback_and_lint(stored, url) -> None:
    result = stored[1]
    assert result["stored"]["version"] == 2 and result["stored"]["active"] is True
    history = _history(url)
    assert [v["version"] for v in history["versions"]] == [1, 2] and history["active_version"] == 2
    assert history["versions"][1]["imu"] == [{"edge": f"imu:{CAM}", "status": "accepted"}]
    assert cli(url, "rig", "lint", MONO).exit_code == 0
    back = cli(url, "rig", "rollback", MONO, "--to", "1", "--reason", "try the pinned camera alone")
    assert back.exit_code == 0, back.output
    assert _history(url)["active_version"] == 1
    camchain = _yaml_body(cli(url, "rig", "export", MONO, "--format", "kalibr").stdout)
    assert set(camchain) == {"cam0"} and "T_cam_imu" not in camchain["cam0"]  # version 1: no IMU yet
    assert cli(url, "rig", "rollback", MONO, "--to", "2", "--reason", "with the IMU").exit_code == 0
    assert _history(url)["active_version"] == 2


def test_kalibrs_camchain_imucam_has_the_one_camera_with_T_cam_imu_and_td(stored, url, tmp_path) -> None:
    estimate = stored[1]["estimate"]
    path = tmp_path / "camchain-imucam.yaml"
    assert cli(url, "rig", "export", MONO, "--format", "kalibr", "-o", str(path)).exit_code == 0
    camchain = _yaml_body(path.read_text())  # Kalibr's own reader: plain safe_load
    assert set(camchain) == {"cam0"} and camchain["cam0"]["cam_overlaps"] == []
    assert np.allclose(camchain["cam0"]["T_cam_imu"], estimate["T_cam_imu"], atol=1e-9)
    assert camchain["cam0"]["timeshift_cam_imu"] == pytest.approx(estimate["timeshift_cam_imu_s"], abs=1e-9)
    linted = cli(url, "lint", str(path))
    assert linted.exit_code == 0 and "(kalibr): pass" in linted.stdout, linted.output


def test_tf_urdf_the_bundle_and_the_report_carry_the_imu_frame(stored, url, tmp_path) -> None:
    tf = _yaml_body(cli(url, "rig", "export", MONO, "--format", "tf").stdout)
    (transform,) = tf["transforms"]
    assert (transform["header"]["frame_id"], transform["child_frame_id"]) == ("imu", CAM_FRAME)
    name, root, joints = loadable_urdf(cli(url, "rig", "export", MONO, "--format", "urdf").stdout)
    assert (name, root, set(joints)) == (MONO, "imu", {CAM_FRAME})
    bundle = tmp_path / "bundle"
    assert cli(url, "rig", "export", MONO, "--format", "bundle", "-o", str(bundle)).exit_code == 0
    manifest = json.loads((bundle / "manifest.json").read_text())
    assert manifest["stereo"] is None and manifest["stereo_pairs"] == []
    assert {"imu.yaml", "camchain.yaml", "cam_0001.yaml", "rig.urdf"} <= {p.name for p in bundle.iterdir()}
    linted = cli(url, "lint", str(bundle / "manifest.json"))
    assert linted.exit_code == 0 and "(bundle): pass" in linted.stdout, linted.output
    page = tmp_path / "rig.html"
    assert cli(url, "report", "--rig", MONO, "-o", str(page)).exit_code == 0
    assert 'data-key="imu_t_' in page.read_text()  # the report's camera-IMU section
    one = tmp_path / "cam.yaml"  # one camera: its camera_info may be one file
    assert cli(url, "rig", "export", MONO, "--format", "ros", "-o", str(one)).exit_code == 0
    assert _yaml_body(one.read_text())["camera_name"] == "cam_0001"


def test_a_recalibrated_camera_makes_the_edge_stale_until_the_rig_is_solved_again(url) -> None:
    with Store.open(url) as store:
        store.add_artifact(calibration(serial=CAM, fx=805.0), activate=True, **WHO)
    stale = cli(url, "rig", "lint", MONO)
    assert stale.exit_code == 1 and "rig-stale-member" in stale.stdout, stale.output
    again = cli(url, "rig", "solve", MONO, "--json")
    assert again.exit_code == 0, again.output
    doc = json.loads(again.stdout)
    assert doc["version"] == 3 and doc["members"][0]["version"] == 2
    assert doc["edges"] == [] and [f["rule"] for f in doc["lint"]] == ["imu-dropped"]
