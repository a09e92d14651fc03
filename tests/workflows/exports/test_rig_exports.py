"""Each rig export read back the way its consumer reads it, and checked against the geometry it encodes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics.rig_metrics import skew
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_tree import pose_to_T
from calibctl.errors import FileSystemError, InputError
from calibctl.workflows.exports.rig_exports import (
    kalibr_camchain,
    kalibr_target,
    opencv_stereo,
    ros_stereo_pair,
    solution_sha256,
    tf_static,
    urdf_joints,
    urdf_robot,
    write_exports,
)
from tests.core.rig_sessions import corner_session, true_members
from tests.workflows.urdf_check import loadable_urdf

UNDISTORT_TOL_PX = 1e-3


@pytest.fixture(scope="module")
def stereo():
    truth, views = corner_session(2, seed=40, baselines_m=(0.075,))
    return solve_rig(views, true_members(truth))


def _points_left(n=30, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-0.2, 0.2, n), rng.uniform(0.5, 3.0, n)])


def _matrix(block):
    return np.array(block["data"], dtype=np.float64).reshape(block["rows"], block["cols"])


def test_ros_pair_encodes_the_stereo_geometry(stereo):
    left, right = stereo.members
    T_rl = stereo.T_a_b(1, 0)
    info_l, info_r = (yaml.safe_load(t) for t in ros_stereo_pair(left, right, T_rl))
    P1, P2 = _matrix(info_l["projection_matrix"]), _matrix(info_r["projection_matrix"])
    R1, R2 = _matrix(info_l["rectification_matrix"]), _matrix(info_r["rectification_matrix"])
    baseline_m = np.linalg.norm(T_rl[:3, 3])
    assert P1[0, 3] == 0.0 and P2[0, 3] == pytest.approx(-P2[0, 0] * baseline_m, rel=1e-9)
    # what image_geometry does: raw pixel -> undistortPoints(K, D, R, P); then depth = -Tx / disparity
    X_l = _points_left()
    X_r = (T_rl[:3, :3] @ X_l.T).T + T_rl[:3, 3]
    raw_l = cv2.projectPoints(
        X_l,
        np.zeros(3),
        np.zeros(3),
        _matrix(info_l["camera_matrix"]),
        np.array(info_l["distortion_coefficients"]["data"]),
    )[0]
    raw_r = cv2.projectPoints(
        X_r,
        np.zeros(3),
        np.zeros(3),
        _matrix(info_r["camera_matrix"]),
        np.array(info_r["distortion_coefficients"]["data"]),
    )[0]
    rect_l = cv2.undistortPoints(
        raw_l,
        _matrix(info_l["camera_matrix"]),
        np.array(info_l["distortion_coefficients"]["data"]),
        R=R1,
        P=P1,
    ).reshape(-1, 2)
    rect_r = cv2.undistortPoints(
        raw_r,
        _matrix(info_r["camera_matrix"]),
        np.array(info_r["distortion_coefficients"]["data"]),
        R=R2,
        P=P2,
    ).reshape(-1, 2)
    # cv2.undistortPoints iterates 5 times by default (as image_geometry calls it): 1e-3 px, not 1e-12
    assert np.max(np.abs(rect_l[:, 1] - rect_r[:, 1])) < UNDISTORT_TOL_PX
    depth = -P2[0, 3] / (rect_l[:, 0] - rect_r[:, 0])
    assert np.allclose(depth, (R1 @ X_l.T)[2], rtol=1e-4)


def test_a_vertical_pair_has_no_ros_export(stereo):
    left, right = stereo.members
    T = np.eye(4)
    T[:3, 3] = [0.0, -0.1, 0.0]
    with pytest.raises(InputError, match="vertical pair"):
        ros_stereo_pair(left, right, T)


def test_opencv_file_reads_back_with_filestorage(stereo, tmp_path):
    left, right = stereo.members
    T_rl = stereo.T_a_b(1, 0)
    path = tmp_path / "stereo.yaml"
    path.write_text(opencv_stereo(left, right, T_rl), encoding="utf-8")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    read = {
        k: fs.getNode(k).mat()
        for k in ("K1", "D1", "K2", "D2", "R", "T", "E", "F", "R1", "R2", "P1", "P2", "Q")
    }
    assert int(fs.getNode("image_width").real()) == 640
    fs.release()
    assert np.allclose(read["R"], T_rl[:3, :3]) and np.allclose(read["T"].ravel(), T_rl[:3, 3])
    assert np.allclose(read["E"], skew(read["T"].ravel()) @ read["R"])
    X_l = _points_left()
    X_r = (read["R"] @ X_l.T).T + read["T"].ravel()
    x_l = (read["K1"] @ (X_l / X_l[:, 2:]).T).T
    x_r = (read["K2"] @ (X_r / X_r[:, 2:]).T).T
    assert np.max(np.abs(np.sum(x_r * (read["F"] @ x_l.T).T, axis=1))) < 1e-6
    assert read["Q"].shape == (4, 4) and read["P2"].shape == (3, 4)


def test_tf_static_and_urdf_give_back_the_tree(stereo):
    edge = stereo.tree.edges[0]
    doc = yaml.safe_load(tf_static(stereo.tree))["transforms"][0]
    assert (doc["header"]["frame_id"], doc["child_frame_id"]) == ("CAM0", "CAM1")
    q = doc["transform"]["rotation"]
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    assert np.allclose(R, edge.T_parent_child[:3, :3], atol=1e-12)
    t = doc["transform"]["translation"]
    assert np.allclose([t["x"], t["y"], t["z"]], edge.T_parent_child[:3, 3])
    urdf = urdf_joints(stereo.tree)
    rpy = [float(v) for v in urdf.split('rpy="')[1].split('"')[0].split()]
    Rx, Ry, Rz = (cv2.Rodrigues(np.eye(3)[i] * a)[0] for i, a in enumerate(rpy))
    assert np.allclose(Rz @ Ry @ Rx, edge.T_parent_child[:3, :3], atol=1e-8)
    assert '<parent link="CAM0"/>' in urdf and '<child link="CAM1"/>' in urdf


def test_the_urdf_is_a_robot_ros_loads_and_the_fragment_stays(stereo):
    """It was a joints-only fragment: no <robot>, no <link>, so neither check_urdf nor robot_state_publisher
    loaded it. The fragment is still there for URDFs that include it."""
    text = urdf_robot(stereo.tree, "stereo-front")
    name, root, joints = loadable_urdf(text)
    assert (name, root, set(joints)) == ("stereo-front", "CAM0", {"CAM1"})
    origin = joints["CAM1"].find("origin")
    xyz = [float(v) for v in origin.get("xyz").split()]
    assert np.allclose(xyz, stereo.tree.edges[0].T_parent_child[:3, 3], atol=1e-9)
    fragment = urdf_joints(stereo.tree)
    assert "<robot" not in fragment and fragment in text  # the same joints, inside a robot
    assert loadable_urdf(urdf_robot(stereo.tree, 'a "quoted" & <odd> name'))[0] == 'a "quoted" & <odd> name'


def test_kalibr_chain_maps_the_previous_camera_into_the_next(stereo):
    doc = yaml.safe_load(kalibr_camchain(stereo.members, stereo.tree))
    assert set(doc) == {"cam0", "cam1"} and "T_cn_cnm1" not in doc["cam0"]
    assert np.allclose(np.array(doc["cam1"]["T_cn_cnm1"]), stereo.T_a_b(1, 0))
    assert doc["cam1"]["distortion_model"] == "radtan" and len(doc["cam1"]["distortion_coeffs"]) == 4


def test_kalibr_refuses_a_k3_model(stereo):
    members = list(stereo.members)
    members[1] = type(members[1])(
        members[1].name, members[1].camera_matrix, np.array([-0.2, 0.1, 0, 0, 0.01]), members[1].image_size
    )
    with pytest.raises(InputError, match="radtan model has no k3"):
        kalibr_camchain(members, stereo.tree)


def test_write_exports_writes_every_file(stereo, tmp_path):
    names = {p.name for p in write_exports(stereo, tmp_path / "x")}
    assert loadable_urdf((tmp_path / "x" / "rig.urdf.xml").read_text())[1] == "cam0_optical_frame"
    assert names == {
        "stereo_CAM0_CAM1.yaml",
        "tf_static.yaml",
        "rig.urdf.xml",
        "camchain.yaml",
        "CAM0_camera_info.yaml",
        "CAM1_camera_info.yaml",
    }
    assert pose_to_T(np.zeros(6)).shape == (4, 4)


def test_solution_sha256_follows_the_numbers_the_exports_are_made_of(stereo):
    from dataclasses import replace

    sha = solution_sha256(stereo)
    assert sha == solution_sha256(stereo) and len(sha) == 64
    edge = stereo.tree.edges[0]
    moved = edge.T_parent_child.copy()
    moved[0, 3] += 1e-6  # a micrometre
    tree = replace(stereo.tree, edges=(replace(edge, T_parent_child=moved),))
    assert solution_sha256(replace(stereo, tree=tree)) != sha


def test_an_export_folder_that_cannot_be_created_is_a_file_system_error(stereo, tmp_path):
    (tmp_path / "plain").write_text("x")
    with pytest.raises(FileSystemError, match=r"cannot create the export folder .*plain/out") as refused:
        write_exports(stereo, tmp_path / "plain" / "out")
    assert refused.value.exit_code == 2


@pytest.mark.parametrize(
    ("board", "says"),
    [
        (BoardSpec.charuco(10, 7, 0.03, 0.022), "is a ChArUco board"),
        (BoardSpec.aprilgrid(6, 6, 0.088, 0.3, family="25h9"), "is an AprilGrid of DICT_APRILTAG_25h9"),
        (BoardSpec.aprilgrid(2, 6, 0.088, 0.3), "is 2 x 6: Kalibr reads no target under 3 x 3"),
    ],
    ids=["charuco", "other family", "2 tags wide"],
)
def test_a_board_kalibr_cannot_read_is_no_target_yaml(board, says) -> None:
    with pytest.raises(InputError, match=says):
        kalibr_target(board, "B@1")
