"""The bundle of a rendered stereo rig read by the consumers' own code: ROS camera_calibration_parsers (its
C++ parser) and image_geometry's StereoCameraModel, mrcal, Debian's OpenCV (cv2.FileStorage), urdfdom's
check_urdf. Each camera's projection must match calibctl's to 1e-6 px, left and right not swapped.

The consumers are Debian packages for the system python (``make test-consumers`` installs them:
python3-camera-calibration-parsers python3-image-geometry python3-mrcal liburdfdom-tools); each part skips,
saying which, when its consumer is absent. The checks with the project's own cv2 and the URDF rules of
tests/workflows/urdf_check.py run everywhere.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from calibctl.artifacts.rig import RigCalibration
from calibctl.core.extrinsics.rig_metrics import rectify
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics
from tests.cli.rig.test_rig_export_cli import db, invoke, rig2, solved  # noqa: F401 - fixtures
from tests.workflows.urdf_check import loadable_urdf

PROJECTION_TOL_PX = 1e-6
SYSTEM_PYTHON = Path("/usr/bin/python3")
CONSUMERS = Path(__file__).parents[2] / "workflows" / "exports" / "robot_consumers.py"


def _points_root(n=40, seed=3):
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.6, 3.0, n)
    return np.column_stack([rng.uniform(-0.25, 0.25, n) * z, rng.uniform(-0.18, 0.18, n) * z, z])


class Truth:
    """calibctl's own projections of the stored rig (cv2.projectPoints on the members, rectify on the
    pair)."""

    def __init__(self, cal: RigCalibration, X: np.ndarray, left: str = "CAM0", right: str = "CAM1") -> None:
        m = {x.serial: x for x in cal.members}
        self.K = {s: np.array(x.camera_matrix) for s, x in m.items()}
        self.D = {s: np.array(x.dist_coeffs) for s, x in m.items()}
        T_left_right = np.array(cal.edges[0].T_parent_child)
        self.T_right_left = np.linalg.inv(T_left_right)
        R, t = self.T_right_left[:3, :3], self.T_right_left[:3, 3]
        self.left, self.right = left, right
        self.raw = {
            left: cv2.projectPoints(X, np.zeros(3), np.zeros(3), self.K[left], self.D[left])[0].reshape(
                -1, 2
            ),
            right: cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, self.K[right], self.D[right])[0].reshape(
                -1, 2
            ),
        }
        members = [
            MemberIntrinsics(s, self.K[s], self.D[s], m[s].image_size, lens=m[s].lens) for s in (left, right)
        ]
        self.rect = rectify(members[0], members[1], self.T_right_left)
        Xh = np.column_stack([(self.rect.R1 @ X.T).T, np.ones(len(X))])
        self.rectified = {
            s: (P @ Xh.T).T[:, :2] / (P @ Xh.T).T[:, 2:]
            for s, P in ((left, self.rect.P1), (right, self.rect.P2))
        }


@pytest.fixture
def bundle(db, tmp_path):
    out = tmp_path / "bundle"
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out))
    assert r.exit_code == 0, r.output
    cal = RigCalibration.model_validate_json((out / "rig.json").read_text())
    return out, cal


def test_the_bundle_reads_right_with_the_projects_own_opencv_and_urdf_rules(bundle):
    out, cal = bundle
    X = _points_root()
    truth = Truth(cal, X)
    manifest = json.loads((out / "manifest.json").read_text())
    assert (manifest["stereo"]["left"], manifest["stereo"]["right"]) == ("CAM0", "CAM1")
    fs = cv2.FileStorage(str(out / manifest["stereo_pairs"][0]["opencv"]), cv2.FILE_STORAGE_READ)
    K1, D1, K2, D2, R, T = (fs.getNode(k).mat() for k in ("K1", "D1", "K2", "D2", "R", "T"))
    fs.release()
    right = cv2.projectPoints(X, cv2.Rodrigues(R)[0], T, K2, D2)[0].reshape(-1, 2)
    assert np.max(np.abs(right - truth.raw["CAM1"])) < PROJECTION_TOL_PX
    assert (
        np.max(
            np.abs(
                cv2.projectPoints(X, np.zeros(3), np.zeros(3), K1, D1)[0].reshape(-1, 2) - truth.raw["CAM0"]
            )
        )
        < PROJECTION_TOL_PX
    )
    assert np.min(np.abs(truth.raw["CAM1"][:, 0] - truth.raw["CAM0"][:, 0])) > 1.0  # a swap could not pass
    for serial, name in (("CAM0", "cam0.yaml"), ("CAM1", "cam1.yaml")):
        info = yaml.safe_load((out / name).read_text())
        assert np.allclose(
            np.reshape(info["camera_matrix"]["data"], (3, 3)), truth.K[serial], rtol=1e-15, atol=0
        )
    _, root, joints = loadable_urdf((out / "rig.urdf").read_text())
    assert root == "cam0_optical_frame" and set(joints) == {"cam1_optical_frame"}


def _consumers(out: Path, X: np.ndarray, tmp_path: Path) -> dict:
    if not SYSTEM_PYTHON.exists():
        pytest.skip("no /usr/bin/python3: the Debian consumers are not installed (make test-consumers)")
    points = tmp_path / "points.json"
    points.write_text(json.dumps({"root_points_m": X.tolist()}))
    run = subprocess.run(
        [str(SYSTEM_PYTHON), str(CONSUMERS), str(out), str(points)],
        capture_output=True,
        text=True,
        check=False,
    )
    if run.returncode != 0 and (
        "No module named 'numpy'" in run.stderr or "No module named 'cv2'" in run.stderr
    ):
        pytest.skip("the system python has no numpy / cv2 (make test-consumers installs python3-opencv)")
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def _check_consumers(
    out: Path, cal: RigCalibration, tmp_path: Path, left: str = "CAM0", right: str = "CAM1"
) -> None:
    """Every consumer's projection of the points equals calibctl's to PROJECTION_TOL_PX, each camera its
    own."""
    X = _points_root()
    truth = Truth(cal, X, left, right)
    got = _consumers(out, X, tmp_path)
    skipped = [name for name in ("ros", "image_geometry", "mrcal") if got[name] is None]
    assert (got["opencv"]["left"], got["opencv"]["right"]) == (left, right)
    for side in ("left", "right"):
        serial = got["opencv"][side]
        assert (
            np.max(np.abs(np.array(got["opencv"][f"{side}_px"]) - truth.raw[serial])) < PROJECTION_TOL_PX
        ), side
    if got["ros"] is not None:
        for serial, R, P in ((left, truth.rect.R1, truth.rect.P1), (right, truth.rect.R2, truth.rect.P2)):
            info = got["ros"][serial]
            assert info["camera_name"] == serial.lower()
            assert np.allclose(np.reshape(info["K"], (3, 3)), truth.K[serial], rtol=1e-15, atol=0)
            assert np.allclose(info["D"], truth.D[serial], rtol=1e-15, atol=0)
            assert np.allclose(np.reshape(info["R"], (3, 3)), R, atol=1e-15)
            assert np.allclose(np.reshape(info["P"], (3, 4)), P, rtol=1e-15, atol=1e-12)
        geometry = got["image_geometry"]
        for side, serial in (("left", left), ("right", right)):
            assert (
                np.max(np.abs(np.array(geometry[f"{side}_px"]) - truth.rectified[serial])) < PROJECTION_TOL_PX
            ), side
        assert np.allclose(geometry["depth_m"], geometry["rect_z_m"], rtol=1e-9)
        assert geometry["baseline_m"] == pytest.approx(np.linalg.norm(truth.T_right_left[:3, 3]), rel=1e-9)
    if got["mrcal"] is not None:
        for serial in (left, right):
            assert np.max(np.abs(np.array(got["mrcal"][serial]) - truth.raw[serial])) < PROJECTION_TOL_PX, (
                serial
            )
    assert np.min(np.abs(truth.raw[right][:, 0] - truth.raw[left][:, 0])) > 1.0  # a swap could not pass
    if skipped:
        pytest.skip(
            f"checked Debian OpenCV {got['opencv']['version']}; not installed: {', '.join(skipped)} "
            "(make test-consumers)"
        )


def test_ros_image_geometry_mrcal_and_debian_opencv_read_the_bundle_exactly(bundle, tmp_path):
    out, cal = bundle
    _check_consumers(out, cal, tmp_path)


@pytest.mark.slow
def test_the_opencv_left_right_bundle_reads_the_same_in_every_consumer(tmp_path):
    """Real photos (OpenCV's left01..14 / right01..14, not made by us): calibrate each camera, capture and
    solve
    the rig through the store, export the bundle, read it with the consumers."""
    from calibctl.store.repository import Store
    from tests.artifacts.factories import measured_board
    from tests.datasets import LEFT_RIGHT, require_datasets

    require_datasets()
    for side in ("left", "right"):
        (tmp_path / side).mkdir()
        for path in sorted(LEFT_RIGHT.glob(f"{side}*.jpg")):
            shutil.copy(path, tmp_path / side / path.name)
    url = f"sqlite:///{tmp_path / 's.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    for serial, side in (("LEFT", "left"), ("RIGHT", "right")):
        assert (
            invoke(
                url, "calibrate", "--serial", serial, "--board", "A17", "--source", str(tmp_path / side)
            ).exit_code
            == 0
        )
    assert invoke(url, "rig", "add", "LR", "--camera", "LEFT", "--camera", "RIGHT").exit_code == 0
    assert (
        invoke(
            url,
            "rig",
            "capture",
            "LR",
            "--board",
            "A17",
            "--source",
            f"LEFT={tmp_path / 'left'}",
            "--source",
            f"RIGHT={tmp_path / 'right'}",
        ).exit_code
        == 0
    )
    assert invoke(url, "rig", "solve", "LR").exit_code == 0
    out = tmp_path / "bundle"
    r = invoke(url, "rig", "export", "LR", "--format", "bundle", "-o", str(out))
    assert r.exit_code == 0, r.output
    cal = RigCalibration.model_validate_json((out / "rig.json").read_text())
    assert invoke(url, "lint", str(out / "manifest.json")).exit_code == 0
    _check_consumers(out, cal, tmp_path, "LEFT", "RIGHT")


def test_check_urdf_loads_the_bundle_urdf(bundle):
    out, _ = bundle
    if shutil.which("check_urdf") is None:
        pytest.skip("check_urdf (liburdfdom-tools) is not installed (make test-consumers)")
    run = subprocess.run(["check_urdf", str(out / "rig.urdf")], capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (
        "robot name is: R1" in run.stdout and "root Link: cam0_optical_frame has 1 child(ren)" in run.stdout
    )


def test_the_consumers_read_files_that_carry_a_file_signature(bundle, tmp_path):
    """A standalone export written where a signing key is configured carries one more header line (the
    file's own signature): each consumer reads such a file exactly as before."""
    from calibctl.signing import create_key
    from calibctl.workflows.exports.trace_header import sign_file

    out, cal = bundle
    signer = create_key(tmp_path / "k.pem")
    signed = []
    for path in sorted(out.iterdir()):
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        if (stamped := sign_file(text, signer)) != text:
            path.write_text(stamped)
            signed.append(path.name)
    assert {"cam0.yaml", "cam1.yaml", "rig.urdf"} <= set(signed)
    if shutil.which("check_urdf") is not None:
        run = subprocess.run(
            ["check_urdf", str(out / "rig.urdf")], capture_output=True, text=True, check=False
        )
        assert run.returncode == 0, run.stdout + run.stderr
    _check_consumers(out, cal, tmp_path)
