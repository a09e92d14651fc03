"""`imu solve` from ROS bags read without ROS (ROS 2 sqlite3 and MCAP, ROS 1): the rendered ASL image
recording written as sensor_msgs/Image + sensor_msgs/Imu messages, solved like the folder; a missing
topic, a topic of another type and a repeated image stamp are exit 2 naming the bag and the fix."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.errors import CalibctlError
from calibctl.workflows.imu import imu_solve
from tests.store.rig_documents import RIG
from tests.workflows.imu.imu_data import CAM, TD_S, make_store, rendered, settings_for

rosbags = pytest.importorskip("rosbags")


def _write_bag(
    rec: Path, bag: Path, kind: str = "ros2", repeat_stamp: bool = False, zero_imu_stamps: bool = False
) -> None:
    """``rec`` (the ASL image recording) as a bag: ``kind`` ros2 (sqlite3), ros2-mcap or ros1 (.bag);
    ``repeat_stamp``: the second image stamped as the first; ``zero_imu_stamps``: a driver that leaves
    the IMU's header stamps at zero."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr

    def header(ns: int) -> object:
        stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
        return Header(seq=0, stamp=stamp, frame_id="f") if ros1 else Header(stamp=stamp, frame_id="f")

    if ros1:
        writer = Writer1(bag)
    else:
        plugin = StoragePlugin.MCAP if kind == "ros2-mcap" else StoragePlugin.SQLITE3
        writer = Writer(bag, version=9, storage_plugin=plugin)
    with writer as w:
        imu_c = w.add_connection("/imu0", "sensor_msgs/msg/Imu", typestore=ts)
        cam_c = w.add_connection("/cam0/image_raw", "sensor_msgs/msg/Image", typestore=ts)
        for line in (rec / "imu0" / "data.csv").read_text().splitlines()[1:]:
            c = line.split(",")
            ns, v = int(c[0]), [float(x) for x in c[1:]]
            msg = T["sensor_msgs/msg/Imu"](
                header=header(0 if zero_imu_stamps else ns),
                orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=V3(x=v[0], y=v[1], z=v[2]),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=V3(x=v[3], y=v[4], z=v[5]),
                linear_acceleration_covariance=np.zeros(9),
            )
            w.write(imu_c, ns, serialize(msg, msg.__msgtype__))
        listing = (rec / "cam0" / "data.csv").read_text().splitlines()[1:]
        for i, line in enumerate(listing):
            ns_text, name = line.split(",")
            ns = int(listing[0].split(",")[0]) if repeat_stamp and i == 1 else int(ns_text)
            gray = cv2.imread(str(rec / "cam0" / "data" / name), cv2.IMREAD_GRAYSCALE)
            msg = T["sensor_msgs/msg/Image"](
                header=header(ns),
                height=gray.shape[0],
                width=gray.shape[1],
                encoding="mono8",
                is_bigendian=0,
                step=gray.shape[1],
                data=gray.reshape(-1),
            )
            w.write(cam_c, int(ns_text), serialize(msg, msg.__msgtype__))


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("bag") / "rec"
    _write_bag(rendered(tmp_path_factory, "images"), path)
    return path


@pytest.mark.parametrize("kind", ["ros2", "ros2-mcap", "ros1"])
def test_a_bag_solves_like_the_folder(tmp_path_factory, tmp_path, kind) -> None:
    path = tmp_path / ("rec.bag" if kind == "ros1" else "rec")
    _write_bag(rendered(tmp_path_factory, "images"), path, kind)
    url = make_store(tmp_path / "c.db")
    req = imu_solve.ImuRequest(
        path, CAM, rig=RIG, board="G7", image_topic="/cam0/image_raw", imu_topic="/imu0"
    )
    out = imu_solve.run_imu(settings_for(url), req)
    assert out.stored is not None and out.stored.status == "accepted"
    ev = out.stored.imu[0]
    assert [i.role for i in ev.inputs] == ["bag"] and ev.estimate is not None
    assert abs(ev.estimate.td_s - TD_S) < 5 * ev.estimate.sigma_td_ms / 1e3


@pytest.mark.parametrize(
    ("topics", "message", "hint"),
    [
        (("/cam0/image_raw", "/imu1"), "has no topic /imu1 (it has: /cam0/image_raw", "--imu-topic"),
        (("/imu0", "/imu0"), "topic /imu0 carries sensor_msgs/msg/Imu, not sensor_msgs/msg/Image", "Image"),
        ((None, "/imu0"), "is a ROS bag: name its topics", "--image-topic"),
    ],
)
def test_a_bag_without_the_named_topic_is_exit_2(bag, tmp_path, topics, message, hint) -> None:
    url = make_store(tmp_path / "c.db")
    req = imu_solve.ImuRequest(bag, CAM, board="G7", image_topic=topics[0], imu_topic=topics[1])
    with pytest.raises(CalibctlError) as info:
        imu_solve.run_imu(settings_for(url), req)
    assert info.value.exit_code == 2 and message in info.value.message and hint in (info.value.hint or "")


def test_a_file_of_a_ros2_bag_is_refused_naming_the_bag_folder(bag, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    (storage,) = [p for p in bag.iterdir() if p.name != "metadata.yaml"]  # the .db3 people pick
    req = imu_solve.ImuRequest(storage, CAM, board="G7", image_topic="/cam0/image_raw", imu_topic="/imu0")
    with pytest.raises(CalibctlError, match="is one file of the ROS 2 bag") as info:
        imu_solve.run_imu(settings_for(url), req)
    assert (
        info.value.exit_code == 2
        and info.value.hint == f"give the bag folder {bag} (the one holding metadata.yaml)"
    )


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ({"repeat_stamp": True}, r"image stamp \d+ ns appears 2 times"),
        ({"zero_imu_stamps": True}, r"/imu0: IMU stamp 0 ns appears 720 times"),
    ],
    ids=["image", "imu"],
)
def test_a_repeated_stamp_in_a_bag_is_refused(tmp_path_factory, tmp_path, edit, message) -> None:
    path = tmp_path / "dup"
    _write_bag(rendered(tmp_path_factory, "images"), path, **edit)
    url = make_store(tmp_path / "c.db")
    req = imu_solve.ImuRequest(path, CAM, board="G7", image_topic="/cam0/image_raw", imu_topic="/imu0")
    with pytest.raises(CalibctlError, match=message) as info:
        imu_solve.run_imu(settings_for(url), req)
    assert info.value.exit_code == 2
