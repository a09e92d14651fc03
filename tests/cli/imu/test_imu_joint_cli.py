"""`calibctl imu solve` with two cameras against one IMU: one joint solve, the truth within each
camera's sigma; with --rig, a camera the rig already relates to the first is held through that pose and
only the first camera's edge is stored; cameras and serials that do not pair are exit 2 in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calibctl.core.synth.imu import EUROC_LIKE_T_CAM0_CAM1
from calibctl.store.repository import Store
from tests.store.rig_documents import RIG
from tests.workflows.imu.imu_data import CAM, OTHER, TD_S, WHO, cli, make_store, truth

PAIRS = ["--camera", "cam0", "--serial", CAM, "--camera", "cam1", "--serial", OTHER]


@pytest.fixture(scope="module")
def stereo(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    """The store (its rig relating CAM-0001 -> CAM-0002 as rendered, version 2) and a 3 s stereo render."""
    folder = tmp_path_factory.mktemp("imu-stereo")
    url = make_store(folder / "c.db")
    with Store.open(url) as store:
        cal = store.get_rig_calibration(RIG, None)
        edge = cal.edges[0].model_copy(
            update={"T_parent_child": tuple(map(tuple, EUROC_LIKE_T_CAM0_CAM1.tolist()))}
        )
        store.add_rig_calibration(
            cal.model_copy(update={"version": 2, "edges": [edge]}), activate=True, **WHO
        )
    rec = folder / "rec"
    r = cli(url, "imu", "synth", str(rec), "--serial", CAM, "--stereo", "--duration-s", "3", "--seed", "4")
    assert r.exit_code == 0, r.output
    return url, rec


def test_two_cameras_solve_jointly_each_within_its_sigma(stereo) -> None:
    url, rec = stereo
    r = cli(url, "imu", "solve", str(rec), *PAIRS, "--noise", str(rec / "imu.yaml"), "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    t = truth(rec)
    rendered = [np.array(t["T_imu_cam"]), np.array(t["more_cameras"][0]["T_imu_cam"])]
    (more,) = doc["more_cameras"]
    assert (doc["serial"], more["serial"], more["camera_folder"], more["held_by_rig"]) == (
        CAM,
        OTHER,
        "cam1",
        None,
    )
    for d, T in zip((doc, more), rendered, strict=True):
        e = d["estimate"]
        assert d["status"] == "accepted"
        assert abs(e["td_ms"] - TD_S * 1e3) < 5 * e["sigma_td_ms"]
        dt_mm = 1e3 * np.abs(np.array(e["translation_m"]) - T[:3, 3])
        assert np.all(dt_mm < 5 * np.array(e["sigma_translation_mm"]) + 1e-3)  # JSON rounds to a micron
    # One IMU: the biases are one estimate, reported with each camera; each camera has its own row test.
    assert doc["estimate"]["gyro_bias_rad_s"] == more["estimate"]["gyro_bias_rad_s"]
    assert not doc["row_test"]["significant"] and not more["row_test"]["significant"]


def test_with_the_rig_a_related_camera_is_held_and_only_the_first_edge_stored(stereo) -> None:
    url, rec = stereo
    r = cli(url, "imu", "solve", str(rec), *PAIRS, "--noise", str(rec / "imu.yaml"), "--rig", RIG, "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    (more,) = doc["more_cameras"]
    assert more["held_by_rig"] == f"{CAM} -> {OTHER} of rig {RIG}@2" and "stored" not in more
    assert doc["stored"]["version"] == 3
    T0, T1 = np.array(doc["estimate"]["matrix"]), np.array(more["estimate"]["matrix"])
    assert np.allclose(T1, T0 @ EUROC_LIKE_T_CAM0_CAM1, atol=1e-6)
    exported = json.loads(cli(url, "rig", "export", RIG, "--format", "json").stdout)
    (ev,) = exported["imu"]
    assert ev["child_frame"] == CAM
    # The held camera's corners moved the stored edge: the evidence pins both cameras' corner files.
    corners = [i["path"] for i in ev["inputs"] if i["role"] == "corners"]
    assert [Path(p).name for p in corners] == ["cam0", "cam1"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--camera", "cam0", "--camera", "cam1", "--serial", CAM], "2 --camera for 1 --serial"),
        (
            ["--camera", "cam0", "--serial", CAM, "--camera", "cam1", "--serial", CAM],
            f"serial {CAM} is named twice",
        ),
    ],
)
def test_cameras_and_serials_that_do_not_pair_are_exit_2(stereo, args, message) -> None:
    url, rec = stereo
    r = cli(url, "imu", "solve", str(rec), *args)
    assert r.exit_code == 2
    assert message in r.output and "Traceback" not in r.output
