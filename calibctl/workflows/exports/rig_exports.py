"""What a robot loads from a solved rig: ROS stereo camera_info pair, OpenCV stereo FileStorage,
tf_static YAML, a URDF robot (or its joints alone, to paste into another URDF) and a Kalibr camchain.

Frames and units: the tree's ``T_root_cam`` (metres). ROS and OpenCV files describe the pair (first
camera = left, second = right) with ``R, T`` = T_right_left (x_right = R x_left + T) and cv2.stereoRectify
(CALIB_ZERO_DISPARITY, alpha -1): rectification R1/R2 and projections P1/P2, the right camera's
P[0, 3] = Tx = -fx' * baseline_m, as ROS stereo_image_proc expects (a vertical pair is refused for
ROS: stereo_image_proc assumes horizontal rectification). Kalibr: ``T_cn_cnm1`` maps camera n-1's
frame into camera n's, cameras in tree order; pinhole + radtan (k1 k2 p1 p2), or pinhole + equidistant
(k1..k4) for a fisheye member (ROS: distortion_model equidistant). The tree's frames are serials; the
callers rename them to robot frames (``frame_names.FrameNames.tree``) before tf / URDF, and Kalibr topics
and camera_info names come from the same ``FrameNames``.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from xml.sax.saxutils import quoteattr

import cv2
import numpy as np
import yaml

from calibctl.artifacts.common import jcs_bytes, sha256_hex
from calibctl.artifacts.imu import ImuModelEstimate, ImuNoiseModel
from calibctl.artifacts.rig import RigCalibration
from calibctl.core.board.board_spec import APRILGRID, APRILTAG_FAMILIES, CHARUCO, BoardSpec
from calibctl.core.extrinsics.rig_metrics import essential_matrix, fundamental_matrix, rectify
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics
from calibctl.core.extrinsics.rig_solve import RigSolution
from calibctl.core.extrinsics.rig_tree import Edge, RigTree, orient_tree
from calibctl.core.extrinsics.se3 import quaternion_xyzw
from calibctl.errors import InputError
from calibctl.files import file_errors, write_atomic
from calibctl.workflows.exports import trace_header
from calibctl.workflows.exports.frame_names import FrameNames
from calibctl.workflows.exports.ros_camera_info import camera_name_for, distortion_for


def stored_geometry(cal: RigCalibration) -> tuple[list[MemberIntrinsics], RigTree, RigTree]:
    """A stored rig version's members, its camera tree (the rig-solve edges, serials) and its whole tree
    (hand-eye and LiDAR edges and declared frames too), as every rig export reads them."""
    members = [
        MemberIntrinsics(
            m.serial, np.array(m.camera_matrix), np.array(m.dist_coeffs), m.image_size, lens=m.lens
        )
        for m in cal.members
    ]
    edges = [Edge(e.parent, e.child, np.array(e.T_parent_child), np.array(e.covariance)) for e in cal.edges]
    cameras = RigTree(
        cal.root, tuple(e for e, r in zip(edges, cal.edges, strict=True) if r.source == "rig-solve")
    )
    return members, cameras, orient_tree(edges, cal.root)


def urdf_rpy(R: np.ndarray) -> list[float]:
    """(3, 3) rotation -> URDF [roll, pitch, yaw] (fixed axes: R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = float(np.arcsin(-np.clip(R[2, 0], -1.0, 1.0)))
    if abs(np.cos(pitch)) > 1e-9:
        return [float(np.arctan2(R[2, 1], R[2, 2])), pitch, float(np.arctan2(R[1, 0], R[0, 0]))]
    return [float(np.arctan2(-R[1, 2], R[1, 1])), pitch, 0.0]


def ros_info(
    m: MemberIntrinsics, R: np.ndarray, P: np.ndarray, camera_name: str | None = None
) -> dict[str, object]:
    """The camera_info document of one camera: rectification ``R`` (3, 3) and projection ``P`` (3, 4), px."""
    model, dist = distortion_for(
        [float(v) for v in np.ravel(m.dist_coeffs)], "fisheye" if m.lens == "fisheye" else None
    )
    return {
        "image_width": int(m.image_size[0]),
        "image_height": int(m.image_size[1]),
        "camera_name": camera_name or camera_name_for(m.name),
        "camera_matrix": {"rows": 3, "cols": 3, "data": np.asarray(m.camera_matrix, float).ravel().tolist()},
        "distortion_model": model,
        "distortion_coefficients": {"rows": 1, "cols": len(dist), "data": dist},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": np.asarray(R, float).ravel().tolist()},
        "projection_matrix": {"rows": 3, "cols": 4, "data": np.asarray(P, float).ravel().tolist()},
    }


def _yaml(doc: object) -> str:
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)


def ros_stereo_pair(
    left: MemberIntrinsics, right: MemberIntrinsics, T_right_left: np.ndarray, names: FrameNames | None = None
) -> tuple[str, str]:
    """camera_info YAML of the left and the right camera of a horizontal pair."""
    rect = rectify(left, right, T_right_left)
    if not rect.horizontal:
        raise InputError(
            f"{left.name}-{right.name} is a vertical pair; ROS stereo_image_proc rectifies horizontally",
            hint="export the OpenCV stereo file instead, or order the cameras left to right",
        )
    name = (lambda m: names.camera_name(m.name)) if names is not None else (lambda m: None)
    return (
        _yaml(ros_info(left, rect.R1, rect.P1, name(left))),
        _yaml(ros_info(right, rect.R2, rect.P2, name(right))),
    )


def ros_camera_infos(
    members: Sequence[MemberIntrinsics],
    left: str,
    right: str,
    T_right_left: np.ndarray,
    names: FrameNames,
    *,
    mono_if_vertical: bool = False,
) -> tuple[dict[str, str], bool]:
    """One camera_info YAML per camera (serial -> text): the pair ``left``/``right`` with its rectified R/P,
    every other camera as a monocular camera_info (R = I, P = [K | 0]). A vertical pair is an InputError,
    or (``mono_if_vertical``) gets monocular files too; the flag says whether the pair was rectified."""
    by_name = {m.name: m for m in members}
    texts: dict[str, str] = {}
    try:
        texts[left], texts[right] = ros_stereo_pair(by_name[left], by_name[right], T_right_left, names)
    except InputError:
        if not mono_if_vertical:
            raise
    rectified = bool(texts)
    for m in members:
        if m.name not in texts:
            K = np.asarray(m.camera_matrix, float)
            texts[m.name] = _yaml(
                ros_info(m, np.eye(3), np.hstack([K, np.zeros((3, 1))]), names.camera_name(m.name))
            )
    return {m.name: texts[m.name] for m in members}, rectified


def opencv_stereo(left: MemberIntrinsics, right: MemberIntrinsics, T_right_left: np.ndarray) -> str:
    """cv2.FileStorage YAML text with K1 D1 K2 D2, R T E F (T_right_left), R1 R2 P1 P2 Q and the image size.

    Built in memory, so the caller writes it like every other export (write_atomic: --force, folder and
    permission errors as exit 2); cv2.FileStorage opening the file itself raised a bare cv2.error."""
    rect = rectify(left, right, T_right_left)
    fs = cv2.FileStorage(".yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("image_width", int(left.image_size[0]))
    fs.write("image_height", int(left.image_size[1]))
    if left.lens == "fisheye" and right.lens == "fisheye":
        fs.write(
            "distortion_model", "equidistant"
        )  # D1/D2 are cv2.fisheye's k1..k4, as the camera export says
    for key, value in (
        ("K1", left.camera_matrix),
        ("D1", np.ravel(left.dist_coeffs)[None, :]),
        ("K2", right.camera_matrix),
        ("D2", np.ravel(right.dist_coeffs)[None, :]),
        ("R", T_right_left[:3, :3]),
        ("T", T_right_left[:3, 3:4]),
        ("E", essential_matrix(T_right_left)),
        ("F", fundamental_matrix(T_right_left, left.camera_matrix, right.camera_matrix)),
        ("R1", rect.R1),
        ("R2", rect.R2),
        ("P1", rect.P1),
        ("P2", rect.P2),
        ("Q", rect.Q),
    ):
        fs.write(key, np.asarray(value, dtype=np.float64))
    return str(fs.releaseAndGetString())


TfEdge = tuple[
    str, str, Sequence[float], Sequence[float]
]  # parent, child, translation_m xyz, quaternion xyzw


def tf_message(edges: Sequence[TfEdge]) -> str:
    """tf2_msgs/TFMessage YAML (what `ros2 topic echo /tf_static` prints): one TransformStamped per edge,
    parent = header.frame_id. The one tf writer of rig exports and hand-eye results."""
    transforms = [
        {
            "header": {"frame_id": parent},
            "child_frame_id": child,
            "transform": {
                "translation": dict(zip("xyz", map(float, t_m), strict=True)),
                "rotation": dict(zip("xyzw", map(float, q_xyzw), strict=True)),
            },
        }
        for parent, child, t_m, q_xyzw in edges
    ]
    return yaml.safe_dump({"transforms": transforms}, sort_keys=False)


def tf_static(tree: RigTree) -> str:
    """tf_static YAML of every tree edge."""
    return tf_message(
        [
            (e.parent, e.child, e.T_parent_child[:3, 3].tolist(), quaternion_xyzw(e.T_parent_child[:3, :3]))
            for e in tree.edges
        ]
    )


def urdf_joints(tree: RigTree) -> str:
    """Fixed URDF joints, one per tree edge: a fragment to paste into a robot that declares the links."""
    lines = []
    for e in tree.edges:
        xyz = " ".join(f"{v:.9f}" for v in e.T_parent_child[:3, 3])
        rpy = " ".join(f"{v:.9f}" for v in urdf_rpy(e.T_parent_child[:3, :3]))
        lines += [
            f'<joint name={quoteattr(f"{e.parent}_to_{e.child}")} type="fixed">',
            f"  <parent link={quoteattr(e.parent)}/>",
            f"  <child link={quoteattr(e.child)}/>",
            f'  <origin xyz="{xyz}" rpy="{rpy}"/>',
            "</joint>",
        ]
    return "\n".join(lines) + "\n"


def urdf_robot(tree: RigTree, name: str, comment: str | None = None) -> str:
    """A complete URDF document: ``<robot name>`` with a ``<link>`` per frame of the tree (its root the one
    root link) and ``urdf_joints``' fixed joints, what check_urdf, urdf_parser_py and robot_state_publisher
    load as they are. ``comment`` (no ``--``) goes after the XML declaration."""
    header = '<?xml version="1.0"?>\n' + (f"<!-- {comment} -->\n" if comment else "")
    links = "".join(f"<link name={quoteattr(frame)}/>\n" for frame in tree.frames)
    return f"{header}<robot name={quoteattr(name)}>\n{links}{urdf_joints(tree)}</robot>\n"


def tree_neighbours(tree: RigTree) -> dict[str, set[str]]:
    """frame -> the frames joined to it by an edge (the default Kalibr ``cam_overlaps``)."""
    out: dict[str, set[str]] = {f: set() for f in tree.frames}
    for e in tree.edges:
        out[e.parent].add(e.child)
        out[e.child].add(e.parent)
    return out


def kalibr_camchain(
    members: Sequence[MemberIntrinsics],
    tree: RigTree,
    names: FrameNames | None = None,
    overlaps: Mapping[str, Collection[str]] | None = None,
    T_cam_imu: Mapping[str, np.ndarray] | None = None,
    timeshift_cam_imu_s: float = 0.0,
    topics: Mapping[str, str] | None = None,
) -> str:
    """Kalibr camchain YAML, cameras in tree order (root first); ``tree`` names cameras by serial.

    Every camera has ``cam_overlaps`` (indices of the cameras it shares views with: ``overlaps``, default its
    tree neighbours), as Kalibr's ConfigReader ``getCamOverlaps`` requires; ``rostopic`` is the camera's
    legal ROS topic (``names``; ``topics``: serial -> the topic given instead). ``T_cam_imu`` (serial ->
    (4, 4), IMU points into the camera frame) adds Kalibr's camchain-imucam fields ``T_cam_imu`` and
    ``timeshift_cam_imu``: ``timeshift_cam_imu_s``, the td_s of a camera-IMU edge (Kalibr's ``t_imu = t_cam
    + shift`` is calibctl's ``t_imu = t_cam + td_s``: the same number), or 0.0 for an IMU joined by hand-eye
    (which estimates no time shift; its
    time-alignment gate checked the motions were synchronised)."""
    by_name = {m.name: m for m in members}
    names = names or FrameNames.of([m.name for m in members])
    index = {name: i for i, name in enumerate(tree.frames)}
    near = overlaps if overlaps is not None else tree_neighbours(tree)
    doc: dict[str, object] = {}
    previous: str | None = None
    for i, name in enumerate(tree.frames):
        m = by_name[name]
        dist = [float(v) for v in np.ravel(m.dist_coeffs)]
        if m.lens != "fisheye" and (len(dist) > 5 or (len(dist) == 5 and dist[4] != 0.0)):
            raise InputError(
                f"camera {name}: Kalibr's radtan model has no k3 or rational terms",
                hint="calibrate the members with --model k1k2 for a Kalibr export",
            )
        K = np.asarray(m.camera_matrix, float)
        entry: dict[str, object] = {
            "camera_model": "pinhole",
            "intrinsics": [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])],
            "distortion_model": "equidistant" if m.lens == "fisheye" else "radtan",
            "distortion_coeffs": dist[:4],
            "resolution": [int(m.image_size[0]), int(m.image_size[1])],
            "rostopic": (topics or {}).get(name) or names.topic(name),
            "cam_overlaps": sorted(index[o] for o in near.get(name, ()) if o in index and o != name),
        }
        if previous is not None:
            entry["T_cn_cnm1"] = tree.T(name, previous).tolist()
        if T_cam_imu is not None and name in T_cam_imu:
            entry["T_cam_imu"] = np.asarray(T_cam_imu[name], float).tolist()
            entry["timeshift_cam_imu"] = float(timeshift_cam_imu_s)
        doc[f"cam{i}"] = entry
        previous = name
    return _yaml(doc)


def kalibr_imu(noise: ImuNoiseModel, rostopic: str = "/imu0", model: ImuModelEstimate | None = None) -> str:
    """Kalibr's imu.yaml: the noise model a camera-IMU edge was weighted with (as given, continuous-time
    densities in SI units), the IMU topic and its measured rate; with a solved IMU ``model``, the fields
    Kalibr's own result imu.yaml carries for it (``model``, ``gyroscopes: M, A, C_gyro_i``,
    ``accelerometers: M``). Without one the file has no ``model`` (Kalibr reads that as ``calibrated``)."""
    doc: dict[str, object] = {
        "accelerometer_noise_density": noise.accel_noise_density,
        "accelerometer_random_walk": noise.accel_random_walk,
        "gyroscope_noise_density": noise.gyro_noise_density,
        "gyroscope_random_walk": noise.gyro_random_walk,
        "rostopic": rostopic,
        "update_rate": round(noise.rate_hz, 3),
    }
    if model is not None:
        doc["model"] = model.model
        doc["accelerometers"] = {"M": [list(row) for row in model.accel_M]}
        doc["gyroscopes"] = {
            "M": [list(row) for row in model.gyro_M],
            "A": [list(row) for row in model.gyro_A],
            "C_gyro_i": [list(row) for row in model.gyro_C_gyro_i],
        }
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=False)


def kalibr_target(board: BoardSpec, ref: str) -> str:
    """Kalibr's target.yaml of the registered board ``ref`` (its measured size, metres), in the fields and
    types Kalibr's ConfigReader ``getTargetParams`` checks: an AprilGrid (36h11, Kalibr's only family) as
    ``tagCols``, ``tagRows`` (ints), ``tagSize``, ``tagSpacing`` (floats); a chessboard as ``checkerboard``
    ``targetCols``, ``targetRows`` (inner corners) and ``rowSpacingMeters``, ``colSpacingMeters``. Kalibr
    has no ChArUco target, and reads no grid under 3 x 3: both refused naming the board."""
    grid = board.tags if board.kind == APRILGRID else (board.cols, board.rows)
    if board.kind == CHARUCO or (board.kind == APRILGRID and board.dictionary != APRILTAG_FAMILIES["36h11"]):
        what = "a ChArUco board" if board.kind == CHARUCO else f"an AprilGrid of {board.dictionary}"
        raise InputError(
            f"board {ref} is {what}: Kalibr reads AprilGrids of tag36h11 and checkerboards only",
            "solve the camera-IMU edge with such a board to export Kalibr's target.yaml",
        )
    if min(grid) < 3:
        raise InputError(
            f"board {ref} is {grid[0]} x {grid[1]}: Kalibr reads no target under 3 x 3",
            "export the target for Kalibr from a board of 3 x 3 or more",
        )
    size_m = float(board.square_size_m)
    doc: dict[str, object] = (
        {"target_type": "aprilgrid", "tagCols": int(grid[0]), "tagRows": int(grid[1]), "tagSize": size_m,
         "tagSpacing": float(board.tag_spacing or 0.0)}
        if board.kind == APRILGRID
        else {"target_type": "checkerboard", "targetCols": int(grid[0]), "targetRows": int(grid[1]),
              "rowSpacingMeters": size_m, "colSpacingMeters": size_m}
    )  # fmt: skip
    return yaml.safe_dump(doc, sort_keys=False)


def solution_sha256(solution: RigSolution) -> str:
    """sha256 of the RFC 8785 form of what every export of an unstored solve is derived from: per camera
    (tree order) its name, image size, K, distortion and lens, and every tree edge's T_parent_child."""
    by_name = {m.name: m for m in solution.members}
    doc = {
        "members": [
            {
                "camera": name,
                "image_size": [int(v) for v in by_name[name].image_size],
                "camera_matrix": np.asarray(by_name[name].camera_matrix, float).tolist(),
                "dist_coeffs": [float(v) for v in np.ravel(by_name[name].dist_coeffs)],
                "lens": by_name[name].lens,
            }
            for name in solution.tree.frames
        ],
        "edges": [
            {
                "parent": e.parent,
                "child": e.child,
                "T_parent_child": np.asarray(e.T_parent_child, float).tolist(),
            }
            for e in solution.tree.edges
        ],
    }
    return sha256_hex(jcs_bytes(doc))


def write_exports(
    solution: RigSolution, out: Path, force: bool = True, robot: str = "rig", status: str = "accepted"
) -> list[Path]:
    """Every export of a solved rig into ``out`` (created); the stereo files for the root and the next camera;
    ``robot`` names the URDF robot. Each file carries the rig trace header of a solve no store holds: ``not
    stored``, the verdict ``status`` and ``solution_sha256`` (and its file-sha256, which ``calibctl lint``
    checks)."""
    with file_errors("create the export folder", out):
        out.mkdir(parents=True, exist_ok=True)
    members, tree = solution.members, solution.tree
    names = FrameNames.of([m.name for m in members])
    left, right = members[0], members[1]
    T_right_left = solution.T_a_b(1, 0)
    written = []
    texts = {
        f"stereo_{left.name}_{right.name}.yaml": opencv_stereo(left, right, T_right_left),
        "tf_static.yaml": tf_static(names.tree(tree)),
        "rig.urdf.xml": urdf_robot(names.tree(tree), robot),
        "camchain.yaml": kalibr_camchain(members, tree, names),
    }
    try:
        info_left, info_right = ros_stereo_pair(left, right, T_right_left, names)
        texts[f"{left.name}_camera_info.yaml"] = info_left
        texts[f"{right.name}_camera_info.yaml"] = info_right
    except InputError:
        pass  # a vertical pair has no ROS stereo export; the other files still describe it
    sha = solution_sha256(solution)
    for name, text in texts.items():
        write_atomic(
            out / name, trace_header.stamp_rig(trace_header.NOT_STORED, status, sha, text), force=force
        )
        written.append(out / name)
    return written
