"""`calibctl export --format lut` / `rig export --format lut`: the maps a robot hands to cv2.remap are
OpenCV's own (0 px) for pinhole, rational and fisheye lenses and a rectified stereo pair; a real photo
remapped with them is OpenCV's remap; `calibctl lint` verifies each map, the signature, and (--db)
refuses a stale LUT."""

from __future__ import annotations

import hashlib
import json
import shutil

import cv2
import numpy as np
import pytest
import yaml

from calibctl.core.extrinsics import se3
from calibctl.signing import create_key
from calibctl.store.repository import Store
from calibctl.workflows.exports import trace_header
from tests.artifacts.factories import calibration
from tests.cli.rig.test_rig_store_cli import RUNNER, app
from tests.datasets import LEFT_RIGHT, needs_datasets
from tests.store.rig_documents import rig_calibration, rig_definition

WHO = {"actor": "qa", "station": "st1", "reason": "test"}
SIZE = (320, 240)
RATIONAL = [-0.21, 0.05, 0.0005, -0.0003, 0.01, 0.02, -0.004, 0.003]
FISHEYE = [0.02, -0.01, 0.003, -0.0005]
# the OpenCV sample's left camera (opencv-left-right, 640x480), as a calibration of it gives
REAL_K, REAL_D = (
    ((536.1, 0.0, 342.4), (0.0, 536.0, 235.6), (0.0, 0.0, 1.0)),
    [-0.265, -0.047, 0.0018, -0.0003, 0.25],
)


def _camera(serial, dist, model="k1k2", size=SIZE, K=None):
    art = calibration(serial=serial, image_size=size, cx=size[0] / 2, cy=size[1] / 2, fx=size[0] * 0.8)
    update = {"dist_coeffs": dist, "model": art.model.model_copy(update={"name": model})}
    if K is not None:
        update["camera_matrix"] = K
    return art.model_copy(update=update).sealed()


def _rig(members, T):
    cal = rig_calibration()
    docs = [
        m.model_copy(
            update={
                "serial": a.serial,
                "content_sha256": a.content_sha256,
                "camera_matrix": a.camera_matrix,
                "dist_coeffs": a.dist_coeffs,
                "image_size": a.image_size,
                "lens": "fisheye" if a.model.name == "fisheye" else "pinhole",
            }
        )
        for m, a in zip(cal.members, members, strict=True)
    ]
    edge = cal.edges[0].model_copy(
        update={
            "parent": docs[0].serial,
            "child": docs[1].serial,
            "T_parent_child": tuple(map(tuple, T.tolist())),
        }
    )
    pair = cal.pairs[0].model_copy(update={"a": docs[0].serial, "b": docs[1].serial})
    return cal.model_copy(
        update={
            "rig": members[0].serial[:4] + "-RIG",
            "root": docs[0].serial,
            "members": docs,
            "edges": [edge],
            "pairs": [pair],
            "fit_rms_px": {d.serial: 0.04 for d in docs},
            "held_out_rms_px": {d.serial: 0.05 for d in docs},
        }
    )


T_PAIR = se3.transform(cv2.Rodrigues(np.array([0.01, -0.03, 0.005]))[0], [0.075, 0.002, -0.001])


@pytest.fixture(scope="module")
def signed_store(tmp_path_factory):
    """A signed store: pinhole, rational, fisheye and a 640x480 camera, and two stereo rigs (pinhole +
    rational, two fisheyes); trusted/ holds its key, other/ a stranger's."""
    folder = tmp_path_factory.mktemp("lutstore")
    key = create_key(folder / "k.pem")
    for name, k in (("trusted", key), ("other", create_key(folder / "stranger.pem"))):
        (folder / name).mkdir()
        (folder / name / "k.pem").write_text(k.public_pem())
    arts = {
        "PIN-1": _camera("PIN-1", [-0.2814, 0.0977, 0.0, 0.0, 0.0]),
        "RAT-1": _camera("RAT-1", RATIONAL, "rational"),
        "FISH-1": _camera("FISH-1", FISHEYE, "fisheye"),
        "FISH-2": _camera("FISH-2", [0.018, -0.008, 0.002, -0.0004], "fisheye"),
        "REAL-L": _camera("REAL-L", REAL_D, "k1k2k3", (640, 480), REAL_K),
    }
    with Store.open(f"sqlite:///{folder / 'c.db'}", create=True, signer=key) as store:
        for art in arts.values():
            store.add_artifact(art, activate=True, **WHO)
        for a, b in (("PIN-1", "RAT-1"), ("FISH-1", "FISH-2")):
            cal = _rig([arts[a], arts[b]], T_PAIR)
            store.add_rig(
                rig_definition(cal.rig).model_copy(
                    update={"cameras": [a, b], "root": a, "design_baselines": []}
                )
            )
            store.add_rig_calibration(cal, activate=True, **WHO)
    return folder


@pytest.fixture
def store(signed_store, tmp_path_factory):
    folder = tmp_path_factory.mktemp("lutcopy")
    shutil.copy(signed_store / "c.db", folder / "c.db")
    return f"sqlite:///{folder / 'c.db'}"


def invoke(db, *args):
    return RUNNER.invoke(app, [*(["--db", db] if db else []), *args], terminal_width=110)


def _export(db, ref, out, *extra):
    r = invoke(db, "export", ref, "--format", "lut", "-o", str(out), *extra)
    assert r.exit_code == 0, r.output
    return yaml.safe_load((out / "lut.yaml").read_text())


def _maps(out, camera):
    return {f["map"]: np.load(out / f["path"]) for f in camera["maps"]}


def _opencv_maps(init, K, D, R, P, size):
    return (*init(K, D, R, P, size, cv2.CV_16SC2), *init(K, D, R, P, size, cv2.CV_32FC1))


def _assert_equal(ours, theirs):
    for name, expected in zip(("map1_16sc2", "map2_16uc1", "map_x_32f", "map_y_32f"), theirs, strict=True):
        assert ours[name].dtype == expected.dtype and np.array_equal(ours[name], expected), name


@pytest.mark.parametrize("serial", ["PIN-1", "RAT-1", "FISH-1"])
def test_a_cameras_maps_are_opencvs_on_the_exported_numbers(store, tmp_path, serial):
    art = Store.open(store).get_artifact(serial)
    K, D = np.array(art.camera_matrix), np.array(art.dist_coeffs)
    free = "--balance" if serial.startswith("FISH") else "--alpha"
    doc = _export(store, serial, tmp_path / "lut", free, "0.5")
    cam = doc["cameras"][0]
    assert (cam["camera_matrix"], cam["dist_coeffs"], cam["image_size"]) == (
        K.tolist(),
        D.tolist(),
        list(SIZE),
    )
    if serial.startswith("FISH"):
        new_K = cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(K, D, SIZE, np.eye(3), balance=0.5)
        theirs = _opencv_maps(cv2.fisheye.initUndistortRectifyMap, K, D, np.eye(3), new_K, SIZE)
        assert cam["balance"] == 0.5 and "alpha" not in cam
    else:
        new_K = cv2.getOptimalNewCameraMatrix(K, D, SIZE, 0.5, SIZE)[0]
        theirs = _opencv_maps(cv2.initUndistortRectifyMap, K, D, None, new_K, SIZE)
        assert cam["alpha"] == 0.5
    assert np.array_equal(np.array(cam["P"])[:, :3], new_K)
    _assert_equal(_maps(tmp_path / "lut", cam), theirs)
    header = trace_header.read((tmp_path / "lut" / "lut.yaml").read_text())
    assert header.ref == f"{serial}@1" and header.intact and header.artifact_sha256 == art.content_sha256
    assert header.signature == art.signature  # the store's signature over the source's content hash


@pytest.mark.parametrize("rig", ["PIN--RIG", "FISH-RIG"])
def test_a_stereo_pairs_rectification_maps_are_opencvs(store, tmp_path, rig):
    out = tmp_path / "rig"
    r = invoke(store, "rig", "export", rig, "--format", "lut", "-o", str(out))
    assert r.exit_code == 0, r.output
    doc = yaml.safe_load((out / "lut.yaml").read_text())
    left, right = doc["cameras"]
    fisheye = rig == "FISH-RIG"
    K1, D1, K2, D2 = (np.array(c[k]) for c in (left, right) for k in ("camera_matrix", "dist_coeffs"))
    # cv2.stereoRectify on the exported numbers (a fisheye pair: without distortion, as the rig's opencv
    # stereo file; cv2.fisheye.stereoRectify fits its P to corners outside a fisheye's image circle)
    Dr1, Dr2 = (np.zeros(5), np.zeros(5)) if fisheye else (D1, D2)
    T_right_left = np.array(left["T_right_left"])  # the pose the export says it rectified with
    assert (
        np.allclose(T_right_left, np.linalg.inv(T_PAIR), atol=1e-12)
        and right["T_right_left"] == left["T_right_left"]
    )
    R1, R2, P1, P2, *_ = cv2.stereoRectify(
        K1, Dr1, K2, Dr2, SIZE, T_right_left[:3, :3], T_right_left[:3, 3:], flags=cv2.CALIB_ZERO_DISPARITY
    )
    init = cv2.fisheye.initUndistortRectifyMap if fisheye else cv2.initUndistortRectifyMap
    for cam, K, D, R, P in ((left, K1, D1, R1, P1), (right, K2, D2, R2, P2)):
        assert np.array_equal(np.array(cam["R"]), R) and np.array_equal(np.array(cam["P"]), P)
        _assert_equal(_maps(out, cam), _opencv_maps(init, K, D, R, P, SIZE))
    header = trace_header.read_rig((out / "lut.yaml").read_text())
    assert header.ref == f"{rig}@1" and header.intact and header.signature is not None
    assert [(m[0], m[2]) for m in header.members] == [
        (f"{c['serial']}@1", c["frame_id"]) for c in (left, right)
    ]


def test_a_rig_lut_lints_with_its_signature_and_is_stale_once_the_rig_is_solved_again(
    store, signed_store, tmp_path
):
    out = tmp_path / "rig"
    assert invoke(store, "rig", "export", "PIN--RIG", "--format", "lut", "-o", str(out)).exit_code == 0
    trusted = str(signed_store / "trusted")
    assert _lint(store, out, "--require-signature", "--trusted-keys", trusted) == (0, [])
    with Store.open(store) as s:
        again = s.get_rig_calibration("PIN--RIG").model_copy(update={"version": 2, "held_out_folds": 4})
        s.add_rig_calibration(again, activate=True, **WHO)
    code, findings = _lint(store, out)
    assert code == 1 and [f["rule"] for f in findings] == ["lut-stale"]
    assert "built from PIN--RIG@1, but the active version of rig PIN--RIG is 2" in findings[0]["message"]
    assert f"calibctl rig export PIN--RIG --format lut -o {out} --force" in findings[0]["fix"]


@needs_datasets
def test_a_real_photo_remapped_with_the_exported_maps_is_opencvs_remap(store, tmp_path):
    doc = _export(store, "REAL-L", tmp_path / "lut")
    ours = _maps(tmp_path / "lut", doc["cameras"][0])
    photo = cv2.imread(str(LEFT_RIGHT / "left01.jpg"))
    assert photo.shape[:2] == (480, 640)
    K, D = np.array(REAL_K), np.array(REAL_D)
    m1, m2, mx, my = _opencv_maps(
        cv2.initUndistortRectifyMap,
        K,
        D,
        None,
        cv2.getOptimalNewCameraMatrix(K, D, (640, 480), 0.0)[0],
        (640, 480),
    )
    fixed = cv2.remap(photo, ours["map1_16sc2"], ours["map2_16uc1"], cv2.INTER_LINEAR)
    assert np.array_equal(fixed, cv2.remap(photo, m1, m2, cv2.INTER_LINEAR))
    floats = cv2.remap(photo, ours["map_x_32f"], ours["map_y_32f"], cv2.INTER_LINEAR)
    assert np.array_equal(floats, cv2.remap(photo, mx, my, cv2.INTER_LINEAR))
    assert not np.array_equal(fixed, photo)  # the lens's distortion was removed, not copied


def _lint(db, path, *extra):
    r = invoke(db, "--json", "lint", str(path), *extra)
    assert r.exit_code in (0, 1), r.output
    return r.exit_code, [f for x in json.loads(r.stdout)["results"] for f in x["findings"]]


def test_lint_passes_a_lut_and_its_signature_and_refuses_a_strangers(store, signed_store, tmp_path):
    _export(store, "PIN-1", tmp_path / "lut")
    assert _lint(store, tmp_path / "lut") == (0, [])
    assert _lint(
        None,
        tmp_path / "lut" / "lut.yaml",
        "--require-signature",
        "--trusted-keys",
        str(signed_store / "trusted"),
    ) == (0, [])
    code, findings = _lint(
        None, tmp_path / "lut", "--require-signature", "--trusted-keys", str(signed_store / "other")
    )
    assert code == 1 and [f["rule"] for f in findings] == ["signature"]


def test_a_stale_lut_is_refused_with_db(store, tmp_path):
    _export(store, "PIN-1", tmp_path / "lut")
    with Store.open(store) as s:
        v2 = s.get_artifact("PIN-1").model_copy(update={"version": 2, "rms_px": 0.25}).sealed()
        s.add_artifact(v2, activate=True, **WHO)
    code, findings = _lint(store, tmp_path / "lut")
    assert code == 1 and findings[0]["rule"] == "lut-stale"
    assert "built from PIN-1@1, but the active version of PIN-1 is 2" in findings[0]["message"]
    assert f"calibctl export PIN-1 --format lut -o {tmp_path / 'lut'} --force" in findings[0]["fix"]
    assert _lint(None, tmp_path / "lut")[0] == 0  # without a store nothing says it is stale


def _rewrite(out, edit):
    """Edit lut.yaml's body and recompute its file-sha256, as anyone with an editor and sha256sum can."""
    path = out / "lut.yaml"
    doc = yaml.safe_load(path.read_text())
    edit(doc)
    lines = [line for line in path.read_text().splitlines(keepends=True) if line.startswith("# calibctl ")]
    body = "".join(lines[:-1]) + yaml.safe_dump(doc, sort_keys=False)
    sha = trace_header.file_sha256(body)
    path.write_text(
        "".join(lines[:-1]) + f"# calibctl file-sha256 {sha}\n" + yaml.safe_dump(doc, sort_keys=False)
    )


def test_bad_luts_are_exit_1_naming_the_file_and_the_fix(store, tmp_path):
    out = tmp_path / "lut"
    _export(store, "PIN-1", out)
    name = "pin_1.map_x_32f.npy"
    good = (out / name).read_bytes()
    (out / name).write_bytes(good[: len(good) // 2])
    code, findings = _lint(store, out)
    assert (
        code == 1
        and findings[0]["message"] == f"{out / name} is truncated ({len(good) // 2} of {len(good)} bytes)"
    )
    assert f"calibctl export PIN-1 --format lut -o {out} --force" in findings[0]["fix"]

    small = tmp_path / "small"  # another image size's map, its sha256 written into the header
    _export(store, "PIN-1", small)
    other = tmp_path / "other"
    _export(store, "REAL-L", other)
    (small / name).write_bytes((other / "real_l.map_x_32f.npy").read_bytes())
    _, findings = _lint(store, small)
    assert any(
        f"{small / name} is a map for 640x480 images; this LUT is for 320x240" in f["message"]
        for f in findings
    )

    outside = tmp_path / "outside"
    _export(store, "PIN-1", outside)
    _rewrite(outside, lambda d: d["cameras"][0]["maps"][0].update(path="../secret.npy"))
    code, findings = _lint(store, outside)
    assert code == 1 and any(
        "names a map outside its folder: '../secret.npy'" in f["message"] for f in findings
    )


@pytest.mark.parametrize(
    ("edit", "says"),
    [
        (lambda d: d.update(cameras=5), "lut.yaml lists no cameras"),
        (lambda d: d["cameras"][0]["maps"][0].pop("path"), "a map of camera pin_1 has no path"),
        (lambda d: d["cameras"][0]["maps"][0].update(path="/etc/passwd"), "names a map outside its folder"),
        (lambda d: d["cameras"][0].update(alpha="all"), "PIN-1's alpha are not what calibration.json"),
        (lambda d: d.update(source=None), "lut.yaml names no source document in its folder"),
    ],
)
def test_a_malformed_header_is_a_finding_naming_the_file_never_a_traceback(store, tmp_path, edit, says):
    out = tmp_path / "lut"
    _export(store, "PIN-1", out)
    _rewrite(out, edit)
    code, findings = _lint(store, out)
    assert code == 1 and any(says in f["message"] for f in findings), findings
    assert all(str(out) in f["message"] and str(out) in f["fix"] for f in findings)


def test_a_forged_map_with_every_checksum_recomputed_is_not_the_map_its_numbers_give(store, tmp_path):
    out = tmp_path / "lut"
    _export(store, "PIN-1", out)
    path = out / "pin_1.map_x_32f.npy"
    forged = np.load(path) + np.float32(1.0)  # every pixel sampled 1 px to the right
    np.save(path, forged)
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    _rewrite(out, lambda d: d["cameras"][0]["maps"][2].update(sha256=sha))
    code, findings = _lint(store, out)
    assert code == 1 and [f["rule"] for f in findings] == ["lut"]
    assert "pin_1.map_x_32f is not the map its numbers give (off by up to 1 px)" in findings[0]["message"]


def test_an_edited_fx_with_its_maps_rebuilt_and_every_checksum_recomputed_is_refused(store, tmp_path):
    """No key is needed to forge the folder's own checksums: the numbers must be the signed calibration's."""
    out = tmp_path / "lut"
    doc = _export(store, "PIN-1", out)
    cam = doc["cameras"][0]
    K = np.array(cam["camera_matrix"])
    K[0, 0] += 1.0  # fx +1 px, the forgery of the issue
    m1, m2, mx, my = _opencv_maps(
        cv2.initUndistortRectifyMap, K, np.array(cam["dist_coeffs"]), None, np.array(cam["P"])[:, :3], SIZE
    )
    for entry, array in zip(cam["maps"], (m1, m2, mx, my), strict=True):
        np.save(out / entry["path"], array)
        entry["sha256"] = hashlib.sha256((out / entry["path"]).read_bytes()).hexdigest()

    def forge(d):
        d["cameras"][0]["camera_matrix"] = K.tolist()
        d["cameras"][0]["maps"] = cam["maps"]

    _rewrite(out, forge)
    code, findings = _lint(store, out)
    assert code == 1 and [f["rule"] for f in findings] == ["lut"]
    assert (
        "PIN-1's camera_matrix are not what calibration.json (the calibration the header"
        in findings[0]["message"]
    )

    other = tmp_path / "other"  # another camera's document, its sha256 written into the header
    _export(store, "RAT-1", other)
    (out / "calibration.json").write_bytes((other / "calibration.json").read_bytes())
    sha = hashlib.sha256((out / "calibration.json").read_bytes()).hexdigest()
    _rewrite(out, lambda d: d["source"].update(document_sha256=sha))
    code, findings = _lint(store, out)
    assert code == 1 and "calibration.json is not the calibration lut.yaml names" in findings[0]["message"]


def test_export_refuses_a_folder_it_did_not_write_and_the_wrong_lens_option(store, tmp_path):
    out = tmp_path / "notes"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    r = invoke(store, "export", "PIN-1", "--format", "lut", "-o", str(out), "--force")
    assert r.exit_code == 2 and "is not a LUT calibctl wrote" in r.output
    assert (out / "notes.txt").read_text() == "mine"
    r = invoke(store, "export", "FISH-1", "--format", "lut", "-o", str(tmp_path / "f"), "--alpha", "0.3")
    assert r.exit_code == 2 and "--alpha applies to the other lens model" in r.output
    assert not (tmp_path / "f").exists()
    r = invoke(store, "export", "PIN-1", "--format", "lut")
    assert r.exit_code == 2 and "pass -o DIR" in r.output
    r = invoke(store, "export", "PIN-1", "--format", "ros", "--alpha", "0.5")
    assert r.exit_code == 2 and "--alpha and --balance apply to --format lut only" in r.output
    _export(store, "PIN-1", tmp_path / "again")
    assert invoke(store, "export", "PIN-1", "--format", "lut", "-o", str(tmp_path / "again")).exit_code == 2
    assert (
        invoke(
            store, "export", "PIN-1", "--format", "lut", "-o", str(tmp_path / "again"), "--force"
        ).exit_code
        == 0
    )
