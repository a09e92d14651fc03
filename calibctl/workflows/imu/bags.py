"""A camera + IMU recording from a ROS bag, read without ROS (the ``rosbags`` package).

ROS 1 ``.bag`` files and ROS 2 bag folders (``metadata.yaml`` with sqlite3 or MCAP storage) alike
(``rosbags.highlevel.AnyReader``). The user names two topics: ``sensor_msgs/Imu`` (angular velocity in
rad/s, linear acceleration in m/s^2, the IMU frame) and ``sensor_msgs/Image`` (mono8, mono16, bgr8,
rgb8, bgra8, rgba8) or ``sensor_msgs/CompressedImage``. Stamps are the messages' ``header.stamp`` (the
sensor's clock, in ns), not the time the bag recorded them. The corners are detected in every image with
the registered board. A topic the bag does not hold, of another type, an image or IMU stamp repeated
(both streams are put in stamp order): exit 2, one line naming the bag and the fix. The bag is bounded
like every input: its size by the input limit per message read (an image over the limit is refused), the
sha256 of the whole bag in the evidence.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np

from calibctl.errors import InputError, MissingExtraError
from calibctl.workflows.imu.recording import (
    Board,
    CameraStream,
    ImuStream,
    Recording,
    assemble,
    board_corners,
    check_board_seen,
    check_image_size,
)

IMU_TYPES = ("sensor_msgs/msg/Imu",)
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
_CHANNELS = {"mono8": 1, "mono16": 1, "bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4}


def is_bag(path: Path) -> bool:
    """A ROS 1 bag file or a ROS 2 bag folder."""
    return (path.is_file() and path.suffix == ".bag") or (path / "metadata.yaml").is_file()


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _gray(msg: Any, source: str) -> np.ndarray:
    import cv2

    if hasattr(msg, "format"):  # CompressedImage
        gray = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise InputError(f"{source}: an image does not decode ({msg.format})", "record it again")
        return gray
    enc = str(msg.encoding).lower()
    if enc not in _CHANNELS:
        raise InputError(
            f"{source}: image encoding {msg.encoding!r} is not one of {', '.join(_CHANNELS)}",
            "record the camera as mono8 or bgr8 (or compressed)",
        )
    dtype = np.uint16 if enc == "mono16" else np.uint8
    row = np.frombuffer(bytes(msg.data), dtype).reshape(int(msg.height), -1)
    pixels = row[:, : int(msg.width) * _CHANNELS[enc]].reshape(int(msg.height), int(msg.width), -1)
    if enc == "mono16":
        return (pixels[:, :, 0].astype(np.uint16) // 256).astype(np.uint8)
    if _CHANNELS[enc] == 1:
        return np.ascontiguousarray(pixels[:, :, 0])
    code = cv2.COLOR_RGB2GRAY if enc.startswith("rgb") else cv2.COLOR_BGR2GRAY
    return cv2.cvtColor(np.ascontiguousarray(pixels[:, :, :3]), code)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    for f in sorted(p for p in ([path] if path.is_file() else path.rglob("*")) if p.is_file()):
        with f.open("rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def _connection(reader: Any, topic: str, types: tuple[str, ...], bag: Path, option: str) -> Any:
    found = [c for c in reader.connections if c.topic == topic]
    if not found:
        have = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
        raise InputError(
            f"{bag} has no topic {topic} (it has: {', '.join(have) or 'none'})",
            f"name the topic with {option}",
        )
    if found[0].msgtype not in types:
        raise InputError(
            f"{bag}: topic {topic} carries {found[0].msgtype}, not {' or '.join(types)}",
            f"name the {' or '.join(t.rsplit('/', 1)[-1] for t in types)} topic with {option}",
        )
    return found[0]


def _in_stamp_order(stamps: list[int], source: str, what: str) -> tuple[np.ndarray, np.ndarray]:
    """A topic's header stamps in order, with the order that sorts its messages (a bag keeps arrival
    order; the sensor stamps decide); a stamp carried twice is refused (a driver leaving stamps at zero)."""
    ns = np.array(stamps, np.int64)
    order = np.argsort(ns, kind="stable")
    ns = ns[order]
    repeated = np.flatnonzero(np.diff(ns) == 0)
    if repeated.size:
        raise InputError(
            f"{source}: {what} stamp {ns[repeated[0]]} ns appears {repeated.size + 1} times",
            "every message must carry its own header stamp: fix the driver's stamping, then record again",
        )
    return ns, order


def read_bag(
    bag: Path,
    image_topic: str,
    imu_topic: str,
    intrinsics: tuple[np.ndarray, np.ndarray, tuple[int, int]],
    board: Board | None,
) -> Recording:
    """The IMU and one camera from ``bag`` on one origin (module docstring)."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError as exc:
        raise MissingExtraError("bags", "reading a ROS bag", exc.name) from None
    if board is None:
        raise InputError(
            f"{bag}: a bag holds images: the board must be named",
            "pass --board NAME[@REV], the registered board the images show",
        )
    from calibctl import bounded

    limit = bounded.max_input_bytes()
    t_imu, gyro, accel, t_cam, objs, imgs = [], [], [], [], [], []
    try:
        with AnyReader([bag]) as reader:
            imu_c = _connection(reader, imu_topic, IMU_TYPES, bag, "--imu-topic")
            cam_c = _connection(reader, image_topic, IMAGE_TYPES, bag, "--image-topic")
            for conn, _, raw in reader.messages(connections=[imu_c, cam_c]):
                if len(raw) > limit:
                    raise InputError(
                        f"{bag}: a {conn.topic} message of {len(raw)} bytes is over the input limit",
                        "raise CALIBCTL_MAX_INPUT_MB if the bag is yours",
                    )
                msg: Any = reader.deserialize(raw, conn.msgtype)
                if conn.topic == imu_topic:
                    t_imu.append(_stamp_ns(msg))
                    w, a = msg.angular_velocity, msg.linear_acceleration
                    gyro.append((w.x, w.y, w.z))
                    accel.append((a.x, a.y, a.z))
                else:
                    gray = _gray(msg, f"{bag} {image_topic}")
                    check_image_size(gray, intrinsics[2], f"{bag} {image_topic}")
                    obj, img = board_corners(gray, board)
                    t_cam.append(_stamp_ns(msg))
                    objs.append(obj)
                    imgs.append(img)
    except (OSError, ValueError, KeyError) as exc:  # rosbags' own errors derive from these
        raise InputError(f"{bag} is not a readable ROS bag: {exc}", "check the path and the bag") from None
    for what, stamps, option in (("IMU", t_imu, imu_topic), ("camera", t_cam, image_topic)):
        if len(stamps) < 2:
            raise InputError(f"{bag}: {len(stamps)} {what} messages on {option}", "record longer")
    check_board_seen(objs, board, f"{bag} {image_topic}")
    cam_ns, order = _in_stamp_order(t_cam, f"{bag} {image_topic}", "image")
    imu_ns, by_stamp = _in_stamp_order(t_imu, f"{bag} {imu_topic}", "IMU")
    return assemble(
        ImuStream(
            f"{bag} {imu_topic}",
            imu_ns,
            np.array(gyro, np.float64)[by_stamp],
            np.array(accel, np.float64)[by_stamp],
        ),
        CameraStream(f"{bag} {image_topic}", cam_ns, [objs[i] for i in order], [imgs[i] for i in order]),
        intrinsics,
        [("bag", bag, _sha256(bag))],
    )
