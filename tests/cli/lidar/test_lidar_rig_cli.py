"""`calibctl lidar solve --rig`: a LiDAR is a frame of the robot's tree, on renders.

An accepted set is the rig's next active version with the edge lidar -> camera (source lidar-board) and the
result sealed inside it; history, show, rollback, lint (stale camera), tf / URDF / bundle exports and the
report carry it. A rejected set is a rejected version with no edge (exit 1); bad inputs are exit 2 with
nothing stored. The good set is solved once per module and each test works on its own copy of that store.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.artifacts.rig import RigCalibration
from calibctl.cli.main import app
from calibctl.core.extrinsics import se3
from calibctl.core.lidar.validation import rotation_from_rpy
from calibctl.store.repository import Store
from calibctl.workflows.lidar.lidar_synth import run_lidar_synth
from tests.artifacts.factories import calibration
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.workflows.handeye.test_rig_handeye import _tf
from tests.workflows.urdf_check import loadable_urdf

WHO = {"actor": "qa", "station": "st1", "reason": "test"}
CAM, OTHER = "CAM-0001", "CAM-0002"
CAM_FRAME = "cam_0001_optical_frame"
BOARD = [
    "--cols",
    "5",
    "--rows",
    "7",
    "--square-mm",
    "95",
    "--backing-mm",
    "610,850",
    "--pattern-offset-mm",
    "2,0",
]
RUNNER = CliRunner()


def _store(url: str, other_calibrated: bool = True) -> None:
    """Rig STEREO-1 (frames lidar, flange) at version 1 over CAM-0001 with the renders' lens (1280x960,
    f 1000 px, no distortion) and CAM-0002 alike; members pinned to the stored calibrations (lint clean)."""
    with Store.open(url) as store:
        arts = [
            store.add_artifact(_lens(serial), activate=True, **WHO)
            for serial in ((CAM, OTHER) if other_calibrated else (CAM,))
        ]
        store.add_rig(rig_definition().model_copy(update={"frames": ["lidar", "flange"]}))
        base = rig_calibration()
        members = [
            m.model_copy(
                update={
                    "content_sha256": a.content_sha256,
                    "image_size": a.image_size,
                    "camera_matrix": a.camera_matrix,
                    "dist_coeffs": a.dist_coeffs,
                }
            )
            for m, a in zip(base.members, arts, strict=False)
        ] + base.members[len(arts) :]
        store.add_rig_calibration(base.model_copy(update={"members": members}), activate=True, **WHO)


def _lens(serial: str, fx: float = 1000.0):
    cam = calibration(serial=serial, fx=fx, image_size=(1280, 960), cx=640.0, cy=480.0)
    return cam.model_copy(update={"dist_coeffs": [0.0] * 5})


def _cli(url: str, *args: str):
    return RUNNER.invoke(app, ["--db", url, *args])


def _solve_args(folder: Path, *extra: str) -> list[str]:
    box = json.loads((folder / "truth.json").read_text())["box"]
    return [
        "lidar",
        "solve",
        "--images",
        str(folder / "images"),
        "--scans",
        str(folder / "scans"),
        *BOARD,
        "--box",
        box,
        *extra,
    ]


@pytest.fixture(scope="module")
def renders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("lidar-renders")
    run_lidar_synth(root / "good", 10, 1, 0.0, False, False)
    run_lidar_synth(root / "one-way", 8, 2, 0.0, True, False)
    return {"good": root / "good", "one-way": root / "one-way"}


@pytest.fixture(scope="module")
def solved(renders, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """A store whose rig got the lidar edge from the good renders (version 2), and the command's JSON."""
    db = tmp_path_factory.mktemp("lidar-store") / "solved.db"
    url = f"sqlite:///{db}"
    _store(url)
    done = _cli(
        url, *_solve_args(renders["good"], "--serial", CAM, "--rig", RIG, "--lidar-frame", "lidar", "--json")
    )
    assert done.exit_code == 0, done.output
    return db, json.loads(done.stdout)


@pytest.fixture
def url(solved, tmp_path: Path) -> str:
    """This test's own copy of the solved store."""
    shutil.copy(solved[0], tmp_path / "calibctl.db")
    return f"sqlite:///{tmp_path / 'calibctl.db'}"


def _cal(url: str, ref: str = RIG) -> RigCalibration:
    done = _cli(url, "rig", "show", ref, "--json")
    assert done.exit_code == 0, done.output
    return RigCalibration.model_validate_json(done.stdout)


def _urdf_T(joint) -> np.ndarray:
    origin = joint.find("origin")
    xyz = [float(v) for v in origin.get("xyz").split()]
    roll, pitch, yaw = (float(v) for v in origin.get("rpy").split())
    return se3.transform(rotation_from_rpy(roll, pitch, yaw), xyz)


def test_an_accepted_set_is_the_rigs_next_active_version_with_the_lidar_edge(solved, url, renders):
    result = solved[1]
    assert result["stored"] == {
        "rig": RIG,
        "version": 2,
        "status": "accepted",
        "active": True,
        "content_sha256": result["stored"]["content_sha256"],
    }
    T = np.array(result["transform"]["matrix"])
    cal = _cal(url)
    assert cal.version == 2 and cal.status == "accepted" and cal.lint == []
    edge = next(e for e in cal.edges if e.source == "lidar-board")
    assert (edge.parent, edge.child) == ("lidar", CAM)
    assert np.allclose(np.array(edge.T_parent_child), T, atol=1e-12)
    truth = np.array(json.loads((renders["good"] / "truth.json").read_text())["T_lidar_cam"])
    assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.01  # the render's T, within a centimetre
    # the evidence is sealed with the version: T, 6x6 covariance, gates, outcomes, held-out figures
    ev = cal.lidar[0]
    assert (ev.parent_frame, ev.child_frame, ev.status, ev.camera) == ("lidar", CAM, "accepted", f"{CAM}@1")
    assert ev.transform is not None and np.allclose(
        np.array(ev.transform.covariance), result["transform"]["covariance"]
    )
    assert [g.gate for g in ev.gates] == [g["gate"] for g in result["gates"]] and all(
        g.passed for g in ev.gates
    )
    assert (
        len(ev.scans_outcomes) == 10
        and ev.metrics is not None
        and ev.metrics.held_out_plane_rms_mm is not None
    )
    assert (
        ev.metrics.held_out_projected_edge_rms_px is not None
        and ev.metrics.held_out_projected_edge_rms_px > 0
    )
    assert cal.content_hash_algorithm == "sha256-rfc8785" and cal.computed_sha256() == cal.content_sha256
    assert cal.model_copy(update={"lidar": []}).computed_sha256() != cal.content_sha256
    covariance = [[v * 2 for v in row] for row in ev.transform.covariance]
    tampered = ev.model_copy(update={"transform": ev.transform.model_copy(update={"covariance": covariance})})
    assert cal.model_copy(update={"lidar": [tampered]}).computed_sha256() != cal.content_sha256
    history = _cli(url, "rig", "history", RIG, "--json")
    versions = json.loads(history.stdout)["versions"]
    assert versions[-1]["lidar"] == [{"edge": f"lidar:{CAM}", "status": "accepted"}]
    lint = _cli(url, "rig", "lint", RIG)
    assert lint.exit_code == 0 and "pass" in lint.stdout
    shown = _cli(url, "rig", "show", RIG)
    assert "T_lidar_CAM-0001" in shown.stdout and "(lidar-board)" in shown.stdout


def test_tf_urdf_and_bundle_carry_the_lidar_frame_with_the_solved_T(solved, url, tmp_path):
    T = np.array(solved[1]["transform"]["matrix"])
    tf = _tf(_cli(url, "rig", "export", RIG, "--format", "tf").stdout)
    assert set(tf) == {
        ("lidar", CAM_FRAME),
        (CAM_FRAME, "cam_0002_optical_frame"),
    }  # the LiDAR roots the tree
    assert np.allclose(tf[("lidar", CAM_FRAME)], T, atol=1e-8)
    urdf = _cli(url, "rig", "export", RIG, "--format", "urdf").stdout
    name, root, joints = loadable_urdf(urdf)
    assert (name, root) == (RIG, "lidar")
    assert joints[CAM_FRAME].find("parent").get("link") == "lidar"
    assert np.allclose(_urdf_T(joints[CAM_FRAME]), T, atol=1e-8)
    bundle = tmp_path / "bundle"
    done = _cli(url, "rig", "export", RIG, "--format", "bundle", "-o", str(bundle))
    assert done.exit_code == 0, done.output
    assert np.allclose(_tf((bundle / "tf_static.yaml").read_text())[("lidar", CAM_FRAME)], T, atol=1e-8)
    assert np.allclose(_urdf_T(loadable_urdf((bundle / "rig.urdf").read_text())[2][CAM_FRAME]), T, atol=1e-8)
    rig_json = json.loads((bundle / "rig.json").read_text())
    assert rig_json["lidar"][0]["parent_frame"] == "lidar" and rig_json["lidar"][0]["status"] == "accepted"
    linted = _cli(url, "lint", str(bundle / "manifest.json"))
    assert linted.exit_code == 0, linted.output
    if shutil.which("check_urdf") is not None:  # urdfdom's own parser (liburdfdom-tools), when installed
        run = subprocess.run(
            ["check_urdf", str(bundle / "rig.urdf")], capture_output=True, text=True, check=False
        )
        assert run.returncode == 0, run.stdout + run.stderr
        assert "root Link: lidar has 1 child(ren)" in run.stdout
    edge = _tf(_cli(url, "rig", "export", RIG, "--format", "tf", "--edge", f"lidar:{CAM}").stdout)
    assert np.allclose(edge[("lidar", CAM_FRAME)], T, atol=1e-8)


def test_rollback_moves_the_lidar_edge_with_the_version(url):
    done = _cli(url, "rig", "rollback", RIG, "--to", "1", "--reason", "lidar edge looked off")
    assert done.exit_code == 0, done.output
    assert _cal(url).version == 1 and not [e for e in _cal(url).edges if e.source == "lidar-board"]
    assert "lidar" not in _tf(_cli(url, "rig", "export", RIG, "--format", "tf").stdout).__repr__()
    assert _cli(url, "rig", "rollback", RIG, "--to", "2", "--reason", "it was fine").exit_code == 0
    assert [e.parent for e in _cal(url).edges if e.source == "lidar-board"] == ["lidar"]


def test_a_camera_recalibrated_since_makes_the_lidar_edge_stale(url):
    with Store.open(url) as store:
        store.add_artifact(_lens(CAM, 1001.0), activate=True, **WHO)
    lint = _cli(url, "rig", "lint", RIG)
    assert lint.exit_code == 1
    assert (
        f"lidar-stale-member: lidar -> {CAM}: solved with {CAM}@1, the active one is now {CAM}@2"
        in lint.stdout
    )
    assert "calibctl lidar solve ... --rig" in lint.stdout
    refused = _cli(url, "rig", "export", RIG, "--format", "tf")  # (the rig's own member is stale too)
    assert refused.exit_code == 1 and "--allow-stale" in refused.output


def test_a_rejected_set_is_a_rejected_version_with_no_edge(renders, url, tmp_path):
    done = _cli(
        url, *_solve_args(renders["one-way"], "--serial", CAM, "--rig", RIG, "--lidar-frame", "lidar")
    )
    assert done.exit_code == 1, done.output
    assert f"stored as rig {RIG}@3 (rejected, never active; no edge)" in done.stdout
    rejected = _cal(url, f"{RIG}@3")
    assert rejected.status == "rejected" and not [e for e in rejected.edges if e.source == "lidar-board"]
    assert rejected.lidar[0].status == "rejected" and rejected.lidar[0].transform is None
    assert [g.gate for g in rejected.lidar[0].gates if not g.passed] == ["lidar-observability"]
    assert _cal(url).version == 2  # the accepted edge stays active
    lint = _cli(url, "rig", "lint", f"{RIG}@3")
    assert (
        lint.exit_code == 1
        and "lidar-gates: lidar -> CAM-0001: gate lidar-observability failed" in lint.stdout
    )
    page = tmp_path / "rejected.html"
    _cli(url, "report", "--rig", f"{RIG}@3", "-o", str(page))
    html = page.read_text()
    assert 'data-key="lidar_status_lidar-CAM-0001">rejected' in html and "no accepted transform" in html
    assert 'data-key="lidar_gate_lidar-CAM-0001_lidar-observability">FAIL' in html


def test_the_rig_report_shows_the_lidar_section_and_the_overlay(url, renders, tmp_path):
    page = tmp_path / "rig.html"
    done = _cli(url, "report", "--rig", RIG, "-o", str(page))
    assert done.exit_code == 0, done.output
    html = page.read_text()
    assert (
        "<h2>LiDAR</h2>" in html and 'data-key="lidar_gate_lidar-CAM-0001_lidar-observability">pass' in html
    )
    assert 'data-key="lidar_overlay_lidar-CAM-0001"' in html and 'src="data:image/jpeg;base64,' in html
    assert "pose1.pcd over pose1.png" in html
    # the LiDAR is a frame of the composed table and the top-down view: met from its child, T_root_lidar =
    # T^-1
    stored = json.loads(_cli(url, "rig", "show", RIG, "--json").stdout)
    T_lidar_cam = np.array(next(e for e in stored["edges"] if e["source"] == "lidar-board")["T_parent_child"])
    x_mm = float(np.linalg.inv(T_lidar_cam)[0, 3] * 1000)
    assert f'data-key="t_lidar_x">{x_mm:.2f}' in html and f"T_{stored['root']}_lidar" in html
    # the images are not in the store: with the solve's image changed the page says so and draws nothing
    image = renders["good"] / "images" / "pose1.png"
    original = image.read_bytes()
    try:
        image.write_bytes(original + b"\0")
        _cli(url, "report", "--rig", RIG, "-o", str(page), "--force")
    finally:
        image.write_bytes(original)
    html = page.read_text()
    assert "data:image/jpeg" not in html and "changed since the solve (sha256 differs)" in html
    scan = renders["good"] / "scans" / "pose1.pcd"
    scan.rename(tmp_path / "pose1.pcd")
    try:
        _cli(url, "report", "--rig", RIG, "-o", str(page), "--force")
    finally:
        (tmp_path / "pose1.pcd").rename(scan)
    html = page.read_text()
    assert "data:image/jpeg" not in html and "images and scans are not in the store" in html
    assert 'data-key="lidar_overlay_missing_lidar-CAM-0001"' in html


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--serial", CAM, "--rig", "NO-SUCH-RIG", "--lidar-frame", "lidar"], "NO-SUCH-RIG"),
        (
            ["--serial", "CAM-0009", "--rig", RIG, "--lidar-frame", "lidar"],
            "camera CAM-0009 is not a member of rig",
        ),
        (
            ["--serial", CAM, "--rig", RIG, "--lidar-frame", "lidar-top"],
            "'lidar-top' is not a legal ROS frame name",
        ),
        (["--serial", CAM, "--rig", RIG, "--lidar-frame", "velodyne"], "frame 'velodyne' is not in rig"),
        (
            ["--serial", OTHER, "--rig", RIG, "--lidar-frame", "lidar"],
            "camera CAM-0002 has no active calibration",
        ),
        (
            ["--rig", RIG, "--lidar-frame", "lidar", "--camera-info", "x.yaml"],
            "--rig takes the camera as --serial",
        ),
        (["--rig", RIG, "--lidar-frame", "lidar"], "--rig needs --serial CAMERA"),
    ],
)
def test_bad_rig_inputs_exit_2_and_store_nothing(renders, tmp_path, args, message):
    url = f"sqlite:///{tmp_path / 'calibctl.db'}"
    _store(url, other_calibrated=False)
    done = _cli(url, *_solve_args(renders["good"], *args))
    assert done.exit_code == 2, done.output
    assert message in done.output and "Traceback" not in done.output
    with Store.open(url) as store:
        assert [c.version for c in store.list_rig_calibrations(RIG)] == [1] and store.active_rig_version(
            RIG
        ) == 1


@pytest.mark.parametrize("option", ["-o", "--tf-static"])
def test_an_existing_output_file_is_refused_before_the_rig_version_is_stored(renders, tmp_path, option):
    url = f"sqlite:///{tmp_path / 'calibctl.db'}"
    _store(url)
    taken = tmp_path / "taken.out"
    taken.write_text("someone else's file\n")
    args = ["--serial", CAM, "--rig", RIG, "--lidar-frame", "lidar", option, str(taken)]
    done = _cli(url, *_solve_args(renders["good"], *args))
    assert done.exit_code == 2, done.output
    assert f"{taken} already exists; nothing was solved or stored" in done.output
    assert "Traceback" not in done.output and taken.read_text() == "someone else's file\n"
    with Store.open(url) as store:
        assert [c.version for c in store.list_rig_calibrations(RIG)] == [1]
