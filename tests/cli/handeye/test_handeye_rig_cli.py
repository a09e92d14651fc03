"""`calibctl handeye ... --rig RIG`: wiring, exit codes and messages, on SQLite and PostgreSQL; a robot-arm
hand-eye on rendered images goes stale when its camera is re-calibrated (`lint --rig` fails)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.workflows.handeye.test_handeye_robot import _write_scene

RUNNER = CliRunner()
WHO = {"actor": "qa", "station": "st1", "reason": "test"}


@pytest.fixture(scope="module")
def in_hand(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _write_scene(tmp_path_factory.mktemp("robot") / "in-hand", True, 3)


@pytest.fixture
def db(db_url: str) -> str:
    with Store.open(db_url) as store:
        store.add_board(measured_board())
        store.add_artifact(calibration(cx=319.5, cy=239.5, board=measured_board()), activate=True, **WHO)
        store.add_artifact(calibration(serial="CAM-0002", board=measured_board()), activate=True, **WHO)
        store.add_rig(rig_definition().model_copy(update={"frames": ["flange", "imu"]}))
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
    return db_url


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


def synth(tmp_path: Path, *extra: str) -> Path:
    out = tmp_path / f"m{len(extra)}.csv"
    assert invoke("sqlite:///unused.db", "synth-motions", str(out), "--force", *extra).exit_code == 0
    return out


def test_accepted_result_is_stored_active_and_shown_in_the_rig(db, tmp_path):
    r = invoke(db, "handeye", str(synth(tmp_path)), "--from", "imu", "--to", "CAM-0002", "--rig", RIG)
    assert r.exit_code == 0, r.output
    assert f"stored as rig {RIG}@2 (active)" in r.stdout
    r = invoke(db, "rig", "show", RIG)
    assert (
        "T_imu_CAM-0002" in r.stdout
        and "(hand-eye)" in r.stdout
        and "hand-eye imu -> CAM-0002: accepted" in r.stdout
    )
    r = invoke(
        db, "rig", "export", RIG, "--format", "tf"
    )  # the fixture's members are not the stored versions
    assert r.exit_code == 1 and "fails `calibctl rig lint` now" in r.output
    r = invoke(db, "rig", "export", RIG, "--format", "tf", "--allow-stale")
    assert r.exit_code == 0 and "child_frame_id: imu" in r.stdout
    r = invoke(
        db, "--json", "handeye", str(synth(tmp_path)), "--from", "imu", "--to", "CAM-0002", "--rig", RIG
    )
    doc = json.loads(r.stdout)
    assert r.exit_code == 0 and doc["stored"] == {
        **doc["stored"],
        "version": 3,
        "status": "accepted",
        "active": True,
    }
    assert doc["result"]["kind"] == "handeye"
    r = invoke(db, "rig", "export", RIG, "--edge", "imu:CAM-0002", "--format", "json", "--allow-stale")
    assert r.exit_code == 0 and json.loads(r.stdout)["content_sha256"] == doc["result"]["content_sha256"]
    r = invoke(db, "rig", "export", RIG, "--edge", "imu:CAM-0002", "--format", "tf", "--allow-stale")
    assert r.exit_code == 0 and r.stdout.count("child_frame_id") == 1 and "frame_id: imu" in r.stdout
    assert (
        "child_frame_id: cam_0002_optical_frame" in r.stdout
    )  # the same robot frame names as the whole tree
    edge_json = tmp_path / "edge.json"
    assert (
        invoke(
            db,
            "rig",
            "export",
            RIG,
            "--edge",
            "imu:CAM-0002",
            "--format",
            "json",
            "--allow-stale",
            "-o",
            str(edge_json),
        ).exit_code
        == 0
    )
    r = invoke(
        db, "--json", "lint", str(edge_json)
    )  # lint reads the hand-eye result it wrote (it refused it)
    assert r.exit_code == 0 and json.loads(r.stdout)["results"][0]["kind"] == "handeye-json", r.output
    named = ("--edge", "imu:CAM-0002", "--format", "json", "--allow-stale", "--frame", "CAM-0002=left_camera")
    r = invoke(db, "rig", "export", RIG, *named, "-o", str(edge_json), "--force")
    edge = json.loads(edge_json.read_text())
    assert edge["ros_frames"] == {"parent_frame": "imu", "child_frame": "left_camera"}  # as the tf names them
    assert edge["content_sha256"] == doc["result"]["content_sha256"]  # the names are the export's choice
    assert invoke(db, "lint", str(edge_json)).exit_code == 0
    r = invoke(db, "rig", "history", RIG)
    assert "hand-eye imu -> CAM-0002 accepted" in r.stdout
    for args, message in (
        (
            ("--edge", "flange:CAM-0001"),
            "has no hand-eye, LiDAR or camera-IMU edge flange -> CAM-0001 (it has: imu:CAM-0002)",
        ),
        (("--edge", "imu"), "--edge must be FROM:TO"),
        (("--edge", "imu:CAM-0002", "--format", "urdf"), "--edge exports json or tf"),
    ):
        r = invoke(db, "rig", "export", RIG, *args, "--allow-stale")
        assert r.exit_code == 2 and message in r.output


def test_rejected_result_is_stored_rejected_and_exit_1(db, tmp_path):
    r = invoke(
        db,
        "handeye",
        str(synth(tmp_path, "--excitation", "corridor")),
        "--from",
        "imu",
        "--to",
        "CAM-0002",
        "--rig",
        RIG,
    )
    assert r.exit_code == 1
    assert f"stored as rig {RIG}@2 (rejected, never active; no edge)" in r.stdout
    r = invoke(db, "lint", "--rig", f"{RIG}@2")
    assert r.exit_code == 1 and "handeye-gates" in r.stdout
    r = invoke(db, "rig", "export", f"{RIG}@2", "--format", "tf")
    assert r.exit_code == 2 and "rejected: a robot must not load it" in r.output
    r = invoke(db, "--json", "rig", "history", RIG)
    doc = json.loads(r.stdout)
    assert doc["active_version"] == 1 and doc["versions"][1]["handeye"] == [
        {"edge": "imu:CAM-0002", "status": "rejected"}
    ]
    r = invoke(
        db, "rig", "export", f"{RIG}@2", "--allow-rejected", "--edge", "imu:CAM-0002", "--format", "tf"
    )
    assert r.exit_code == 2 and "has no transform" in r.output
    r = invoke(db, "rig", "export", f"{RIG}@2", "--allow-rejected", "--edge", "imu:CAM-0002")
    assert r.exit_code == 0 and json.loads(r.stdout)["transform"] is None


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--from", "imu", "--to", "CAM-0002", "--rig", "NOPE"), "unknown rig 'NOPE'"),
        (("--from", "gps", "--to", "CAM-0002", "--rig", RIG), "frame 'gps' is not in rig"),
        (("--from", "CAM-0001", "--to", "CAM-0002", "--rig", RIG), "both cameras of rig"),
        (("--from", "imu", "--to", "flange", "--rig", RIG), "does not connect"),
        (
            ("--from", "imu", "--to", "CAM-0002", "--rig", RIG, "--serial", "CAM-0009", "--images", "."),
            "camera CAM-0009 has no active calibration",
        ),
    ],
)
def test_bad_targets_are_exit_2_naming_what(db, tmp_path, args, message):
    r = invoke(db, "handeye", str(synth(tmp_path)), *args)
    assert r.exit_code == 2, r.output
    assert message in r.output and "Traceback" not in r.output
    with Store.open(db) as store:
        assert [c.version for c in store.list_rig_calibrations(RIG)] == [1]  # nothing stored


def test_robot_arm_edge_goes_stale_when_its_camera_is_recalibrated(db, in_hand):
    r = invoke(
        db,
        "handeye",
        str(in_hand / "poses.csv"),
        "--from",
        "flange",
        "--to",
        "CAM-0001",
        "--images",
        str(in_hand),
        "--serial",
        "CAM-0001",
        "--rig",
        RIG,
    )
    assert r.exit_code == 0, r.output
    assert f"stored as rig {RIG}@2 (active)" in r.stdout
    assert "handeye-stale-member" not in invoke(db, "lint", "--rig", RIG).stdout
    with Store.open(db) as store:
        store.add_artifact(calibration(cx=319.5, cy=239.5, board=measured_board()), activate=True, **WHO)
    r = invoke(db, "lint", "--rig", RIG)
    assert r.exit_code == 1 and "handeye-stale-member" in r.stdout and "CAM-0001@1" in r.stdout
