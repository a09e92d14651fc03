"""`calibctl rig export`: one camera_info per camera (never two YAML documents in one file), robot frame
names (--frame), the bundle (every file + manifest.json, written whole or not at all), stale refusals."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import yaml

from calibctl.store.repository import Store
from calibctl.workflows.exports import trace_header
from tests.cli.rig.test_rig_store_cli import RUNNER, _capture, app
from tests.workflows.rig.test_rig_store_flow import WHO, _truth_artifact, store_members
from tests.workflows.rig_folders_data import rendered_rig


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


@pytest.fixture(scope="module")
def solved(tmp_path_factory, rig2):
    """A store with rig R1 (CAM0 left, CAM1 right, 75 mm) solved once; tests copy it before changing it."""
    path = tmp_path_factory.mktemp("rigdb") / "c.db"
    url = store_members(f"sqlite:///{path}", rig2)
    assert invoke(url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1").exit_code == 0
    assert _capture(url, rig2).exit_code == 0
    assert invoke(url, "rig", "solve", "R1").exit_code == 0
    return path


@pytest.fixture
def db(solved, tmp_path_factory):
    path = tmp_path_factory.mktemp("db") / "c.db"  # not in tmp_path: the tests list what they wrote there
    shutil.copy(solved, path)
    return f"sqlite:///{path}"


def invoke(db, *args):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


def _text(r):
    return " ".join(r.output.split())


def test_ros_writes_one_camera_info_per_camera_each_one_document(db, tmp_path):
    out = tmp_path / "info"
    r = invoke(db, "rig", "export", "R1", "--format", "ros", "-o", str(out))
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["cam0.yaml", "cam1.yaml"]
    left, right = ((out / n).read_text() for n in ("cam0.yaml", "cam1.yaml"))
    docs = [list(yaml.safe_load_all(t)) for t in (left, right)]
    assert [len(d) for d in docs] == [1, 1]  # ROS reads the first document only: there is no second one
    info_l, info_r = docs[0][0], docs[1][0]
    assert (info_l["camera_name"], info_r["camera_name"]) == ("cam0", "cam1")
    assert (
        info_l["projection_matrix"]["data"][3] == 0.0 and info_r["projection_matrix"]["data"][3] < 0.0
    )  # Tx = -fx'B
    header = trace_header.read_rig(right)
    assert header is not None and header.ref == "R1@1" and header.intact
    assert [(m[0], m[2]) for m in header.members] == [("CAM1@1", "cam1_optical_frame")]


def test_ros_takes_a_file_template(db, tmp_path):
    r = invoke(
        db,
        "rig",
        "export",
        "R1",
        "--format",
        "ros",
        "-o",
        str(tmp_path / "{camera}_info.yaml"),
        "--frame",
        "CAM0=front_left_optical_frame",
        "--frame",
        "CAM1=front_right_optical_frame",
    )
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in tmp_path.glob("*_info.yaml")) == [
        "front_left_info.yaml",
        "front_right_info.yaml",
    ]
    r = invoke(db, "rig", "export", "R1", "--format", "ros", "-o", str(tmp_path / "{camera}_info.yaml"))
    assert r.exit_code == 0  # other names: new files, nothing overwritten
    r = invoke(db, "rig", "export", "R1", "--format", "ros", "-o", str(tmp_path / "{camera}_info.yaml"))
    assert r.exit_code == 2 and "already exists" in r.output


@pytest.mark.parametrize("target", [None, "pair.yaml"])
def test_ros_into_one_file_is_refused_naming_the_fix(db, tmp_path, target):
    args = [] if target is None else ["-o", str(tmp_path / target)]
    r = invoke(db, "rig", "export", "R1", "--format", "ros", *args)
    assert r.exit_code == 2, r.output
    assert "ROS reads only the first YAML document of a file" in _text(r) and "-o DIR" in _text(r)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (["CAM0=front-left"], "'front-left' is not a legal ROS frame name"),
        (["CAM0=/front"], "'/front' is not a legal ROS frame name"),
        (["CAM0=9cam"], "'9cam' is not a legal ROS frame name"),
        (["CAM0=a", "CAM0=b"], "--frame maps CAM0 twice (a and b)"),
        (["CAM0=a", "CAM1=a"], "--frame gives CAM0 and CAM1 the same frame a"),
        (["CAM7=a"], "CAM7 is not a frame of this rig"),
        (["CAM0"], "--frame 'CAM0' is not SERIAL=NAME"),
    ],
)
def test_a_bad_frame_map_is_exit_2_naming_it(db, tmp_path, frame, message):
    args = [x for f in frame for x in ("--frame", f)]
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(tmp_path / "b"), *args)
    assert r.exit_code == 2 and message in _text(r), r.output
    assert not (tmp_path / "b").exists()


def test_bundle_writes_every_file_with_a_manifest(db, tmp_path):
    out = tmp_path / "bundle"
    r = invoke(
        db,
        "rig",
        "export",
        "R1",
        "--format",
        "bundle",
        "-o",
        str(out),
        "--frame",
        "CAM0=front_left_optical_frame",
    )
    assert r.exit_code == 0, r.output
    manifest = json.loads((out / "manifest.json").read_text())
    listed = {f["path"] for f in manifest["files"]}
    assert listed == {
        "front_left.yaml",
        "cam1.yaml",
        "stereo_front_left_cam1.yaml",
        "tf_static.yaml",
        "rig.urdf",
        "camchain.yaml",
        "rig.json",
        "front_left.cameramodel",
        "cam1.cameramodel",
    }
    assert {p.name for p in out.iterdir()} == listed | {"manifest.json"}
    assert (manifest["rig"], manifest["version"], manifest["status"]) == ("R1", 1, "accepted")
    members = {m["serial"]: m for m in manifest["members"]}
    assert (
        members["CAM0"]["frame_id"] == "front_left_optical_frame"
        and members["CAM1"]["rostopic"] == "/cam1/image_raw"
    )
    assert all(len(m["content_sha256"]) == 64 and m["version"] == 1 for m in members.values())
    chain = yaml.safe_load((out / "camchain.yaml").read_text())
    assert [c["cam_overlaps"] for c in chain.values()] == [[1], [0]]
    assert [c["rostopic"] for c in chain.values()] == ["/front_left/image_raw", "/cam1/image_raw"]
    tf = yaml.safe_load((out / "tf_static.yaml").read_text())["transforms"]
    assert [(t["header"]["frame_id"], t["child_frame_id"]) for t in tf] == [
        ("front_left_optical_frame", "cam1_optical_frame")
    ]
    baseline_m = np.linalg.norm([tf[0]["transform"]["translation"][k] for k in "xyz"])
    assert baseline_m == pytest.approx(0.075, abs=2e-4)


def test_bundle_never_replaces_a_folder_it_did_not_write(db, tmp_path):
    out = tmp_path / "bundle"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out))
    assert r.exit_code == 2 and f"{out} already exists" in _text(r) and "--force" in _text(r)
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out), "--force")
    assert r.exit_code == 2 and "is not a bundle calibctl wrote" in _text(r)
    assert (out / "mine.txt").read_text() == "keep" and [p.name for p in tmp_path.iterdir()] == ["bundle"]
    shutil.rmtree(out)
    assert invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out)).exit_code == 0
    (out / "rig.urdf").write_text("edited")
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out), "--force")
    assert r.exit_code == 0, r.output
    assert "edited" not in (out / "rig.urdf").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bundle"]  # no temporary folder left beside it


def test_a_stale_rig_is_not_exported_unless_allowed(db, rig2, tmp_path):
    with Store.open(db) as store:
        store.add_artifact(_truth_artifact(rig2, "CAM0"), activate=True, **WHO)
    r = invoke(db, "rig", "export", "R1", "--format", "tf")
    assert r.exit_code == 1 and "rig R1@1 fails `calibctl rig lint` now" in _text(r) and "CAM0@2" in _text(r)
    assert "--allow-stale" in _text(r)
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(tmp_path / "b"))
    assert r.exit_code == 1 and not (tmp_path / "b").exists()
    r = invoke(db, "rig", "export", "R1", "--format", "tf", "--allow-stale")
    assert r.exit_code == 0 and "child_frame_id: cam1_optical_frame" in r.output


def test_lint_rig_require_signature_names_the_unsigned_rig_and_each_unsigned_member(db, tmp_path):
    """It used to report neither: a CI gate with --require-signature passed an unsigned rig."""
    from calibctl.signing import create_key

    key = create_key(tmp_path / "k.pem")
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    (trusted / "k.pub.pem").write_text(key.public_pem())
    r = invoke(db, "--json", "lint", "--rig", "R1", "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 1, r.output
    messages = [
        f["message"] for f in json.loads(r.stdout)["results"][0]["findings"] if f["rule"] == "signature"
    ]
    assert messages == [
        "rig R1@1 is not signed",
        "member CAM0@1 is not signed",
        "member CAM1@1 is not signed",
    ]
    assert invoke(db, "lint", "--rig", "R1").exit_code == 0  # without --require-signature the rig passes
    empty = tmp_path / "empty"
    empty.mkdir()
    r = invoke(db, "lint", "--rig", "R1", "--require-signature", "--trusted-keys", str(empty))
    assert r.exit_code == 2 and "--require-signature needs trusted keys" in r.output


def test_a_bundle_that_fails_half_way_leaves_nothing_behind(db, tmp_path, monkeypatch):
    import errno
    from pathlib import Path

    written = []
    real_write = Path.write_bytes

    def disk_full_on_the_third_file(self, data):
        written.append(self.name)
        if len(written) == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(self, data)

    monkeypatch.setattr(Path, "write_bytes", disk_full_on_the_third_file)
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(tmp_path / "bundle"))
    assert r.exit_code == 2 and "no space left on the device" in _text(r), r.output
    assert list(tmp_path.iterdir()) == []  # neither the bundle nor its temporary folder
