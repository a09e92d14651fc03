"""`calibctl lint` reads every file `calibctl rig export` writes (each format passes), the bundle manifest (a
file edited or removed is exit 1 naming it), ROS-rewritten and other tools' files, OpenCV YAML/XML/JSON."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import yaml

from tests.cli.rig.test_rig_export_cli import db, invoke, rig2, solved  # noqa: F401 - fixtures

SINGLE_FILE_FORMATS = ("json", "opencv", "tf", "urdf", "urdf-joints", "kalibr")


def _lint(db, *paths):
    r = invoke(db, "--json", "lint", *map(str, paths))
    doc = json.loads(r.stdout) if r.exit_code in (0, 1) else None
    return r, doc


def _rules(result_doc):
    return {f["rule"]: f["severity"] for f in result_doc["findings"]}


def test_every_rig_export_format_lints_clean(db, tmp_path):
    paths = []
    for fmt in SINGLE_FILE_FORMATS:
        path = tmp_path / f"rig.{fmt}"
        assert invoke(db, "rig", "export", "R1", "--format", fmt, "-o", str(path)).exit_code == 0, fmt
        paths.append(path)
    assert invoke(db, "rig", "export", "R1", "--format", "ros", "-o", str(tmp_path / "ros")).exit_code == 0
    paths += sorted((tmp_path / "ros").iterdir())
    r, doc = _lint(db, *paths)
    assert r.exit_code == 0, r.output
    kinds = [x["kind"] for x in doc["results"]]
    assert kinds == ["rig-json", "opencv-stereo", "tf", "urdf", "urdf", "kalibr", "ros", "ros"]
    assert all(x["errors"] == 0 and x["warnings"] == 0 for x in doc["results"]), doc


def test_the_bundle_manifest_lints_every_file_and_names_an_edited_or_missing_one(db, tmp_path):
    out = tmp_path / "bundle"
    assert invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out)).exit_code == 0
    r, doc = _lint(db, out / "manifest.json")
    assert r.exit_code == 0, r.output
    assert doc["results"][0]["kind"] == "bundle" and len(doc["results"]) == 1 + 9
    (out / "cam1.yaml").write_text(
        (out / "cam1.yaml").read_text().replace("camera_name: cam1", "camera_name: cam0")
    )
    (out / "rig.urdf").unlink()
    r, doc = _lint(db, out / "manifest.json")
    assert r.exit_code == 1
    messages = " ".join(f["message"] for f in doc["results"][0]["findings"])
    assert f"{out / 'cam1.yaml'} was changed after calibctl wrote it" in messages
    assert f"{out / 'rig.urdf'} is listed in the manifest but missing" in messages
    edited = next(x for x in doc["results"] if x["source"].endswith("cam1.yaml"))
    assert _rules(edited)["content-hash"] == "error"  # its own header says so too


def test_an_edited_rig_export_is_a_content_hash_error(db, tmp_path):
    path = tmp_path / "tf.yaml"
    invoke(db, "rig", "export", "R1", "--format", "tf", "-o", str(path))
    path.write_text(
        path.read_text().replace("child_frame_id: cam1_optical_frame", "child_frame_id: cam9_optical_frame")
    )
    r, doc = _lint(db, path)
    assert r.exit_code == 1 and _rules(doc["results"][0])["content-hash"] == "error"


def test_a_ros_rewritten_camera_info_warns_traceability_and_asks_for_no_new_capture(db, tmp_path):
    invoke(db, "rig", "export", "R1", "--format", "ros", "-o", str(tmp_path / "ros"))
    text = (tmp_path / "ros" / "cam1.yaml").read_text()
    bare = tmp_path / "rewritten.yaml"  # what set_camera_info / the convert tool leave: no comments
    bare.write_text("".join(line + "\n" for line in text.splitlines() if not line.startswith("#")))
    r, doc = _lint(db, bare)
    result = doc["results"][0]
    assert result["kind"] == "ros" and _rules(result) == {"traceability": "warning"}  # pass with a warning
    assert r.exit_code == 0, r.output
    assert not any("capture more views" in (f["fix"] or "") for f in result["findings"])


@pytest.mark.parametrize("ext", [".yaml", ".xml", ".json"])
def test_opencv_filestorage_in_yaml_xml_and_json_is_read_by_content(db, tmp_path, ext):
    path = tmp_path / f"cam{ext}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", np.array([[500.0, 0, 320.0], [0, 500.0, 240.0], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[-0.1, 0.01, 0.0, 0.0, 0.0]]))
    fs.release()
    r, doc = _lint(db, path)
    result = doc["results"][0]
    assert result["kind"] == "opencv", result  # JSON is not mistaken for a broken ROS camera_info
    assert _rules(result)["traceability"] == "warning" and "principal-point" not in _rules(result)
    assert not any(f["rule"].startswith("ros") for f in result["findings"])


def test_another_tools_kalibr_and_tf_are_linted_on_numbers_and_frames(db, tmp_path):
    chain = {
        "cam0": {
            "camera_model": "pinhole",
            "intrinsics": [500.0, 500.0, 320.0, 240.0],
            "distortion_model": "radtan",
            "distortion_coeffs": [0.0, 0.0, 0.0, 0.0],
            "resolution": [640, 480],
            "rostopic": "/LEFT-01/image_raw",
        }
    }
    path = tmp_path / "camchain.yaml"
    path.write_text(yaml.safe_dump(chain))
    r, doc = _lint(db, path)
    messages = {f["rule"]: f["message"] for f in doc["results"][0]["findings"]}
    assert r.exit_code == 1 and doc["results"][0]["kind"] == "kalibr"
    assert "cam0 has no cam_overlaps: Kalibr's getCamOverlaps fails" in messages["kalibr"]
    assert "rostopic '/LEFT-01/image_raw' is not a legal ROS topic" in messages["frames"]
    tf = {
        "transforms": [
            {
                "header": {"frame_id": "base"},
                "child_frame_id": "LEFT-01",
                "transform": {
                    "translation": {"x": 0, "y": 0, "z": 0},
                    "rotation": {"x": 0, "y": 0, "z": 0, "w": 2.0},
                },
            }
        ]
    }
    path = tmp_path / "tf.yaml"
    path.write_text(yaml.safe_dump(tf))
    r, doc = _lint(db, path)
    rules = _rules(doc["results"][0])
    assert r.exit_code == 1 and rules["frames"] == "error" and rules["transform"] == "error"


def test_an_unknown_layout_is_exit_2_naming_what_lint_looked_for(db, tmp_path):
    path = tmp_path / "x.yaml"
    path.write_text("hello: 1\nworld: 2\n")
    r = invoke(db, "lint", str(path))
    assert r.exit_code == 2
    text = " ".join(r.output.split())
    assert (
        "lint looked for a calibctl artifact" in text
        and "Kalibr camchain" in text
        and "bundle manifest.json" in text
    )


@pytest.mark.parametrize("lens", ["pinhole", "fisheye"])
def test_every_format_of_a_pinhole_and_a_fisheye_rig_lints_clean(sqlite_url, tmp_path, lens):
    """Stored rig documents (their members are not the store's active versions: --allow-stale)."""
    from calibctl.store.repository import Store
    from tests.store.rig_documents import RIG, rig_calibration, rig_definition

    cal = rig_calibration()
    if lens == "fisheye":
        members = [
            m.model_copy(update={"lens": "fisheye", "dist_coeffs": [0.02, -0.004, 0.001, -0.0002]})
            for m in cal.members
        ]
        cal = cal.model_copy(update={"members": members})
    with Store.open(sqlite_url) as store:
        store.add_rig(rig_definition())
        store.add_rig_calibration(cal, activate=True, actor="qa", station="st1", reason="test")
    paths = []
    for fmt in SINGLE_FILE_FORMATS:
        paths.append(tmp_path / f"rig.{fmt}")
        r = invoke(sqlite_url, "rig", "export", RIG, "--format", fmt, "-o", str(paths[-1]), "--allow-stale")
        assert r.exit_code == 0, (fmt, r.output)
    out = tmp_path / "bundle"
    assert (
        invoke(
            sqlite_url, "rig", "export", RIG, "--format", "bundle", "-o", str(out), "--allow-stale"
        ).exit_code
        == 0
    )
    manifest = json.loads((out / "manifest.json").read_text())
    if lens == "fisheye":
        assert all(m["mrcal"] is None and "Kannala-Brandt" in m["mrcal_missing"] for m in manifest["members"])
        assert yaml.safe_load((out / "cam_0001.yaml").read_text())["distortion_model"] == "equidistant"
    r, doc = _lint(sqlite_url, *paths, out / "manifest.json")
    assert r.exit_code == 0, r.output
    assert all(x["errors"] == 0 for x in doc["results"]), [x for x in doc["results"] if x["errors"]]


def test_require_signature_refuses_an_unsigned_rig_export_naming_the_fix(db, tmp_path):
    from calibctl.signing import create_key

    trusted = tmp_path / "trusted"
    trusted.mkdir()
    (trusted / "k.pub.pem").write_text(create_key(tmp_path / "k.pem").public_pem())
    path = tmp_path / "tf.yaml"
    invoke(db, "rig", "export", "R1", "--format", "tf", "-o", str(path))
    r = invoke(db, "--json", "lint", str(path), "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 1
    signature = next(f for f in json.loads(r.stdout)["results"][0]["findings"] if f["rule"] == "signature")
    assert signature["message"] == "rig R1@1 is not signed" and "calibctl keys init" in signature["fix"]
