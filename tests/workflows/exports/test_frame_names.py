"""Robot frame names: the default derived from a serial is a legal ROS name; the user's map is checked."""

from __future__ import annotations

import pytest

from calibctl.errors import UsageError
from calibctl.workflows.exports.frame_names import FrameNames, default_frame, is_ros_name, parse_frame_map


@pytest.mark.parametrize(
    ("serial", "camera", "frame"),
    [
        ("LEFT-01", True, "left_01_optical_frame"),
        ("CAM0", True, "cam0_optical_frame"),
        ("0042", True, "cam_0042_optical_frame"),
        ("a.b:c--d", True, "a_b_c_d_optical_frame"),
        ("flange", False, "flange"),
        ("tool0/imu", False, "tool0_imu"),
        ("9axis", False, "frame_9axis"),
    ],
)
def test_default_frames_are_legal_ros_names(serial, camera, frame):
    assert default_frame(serial, camera) == frame and is_ros_name(frame)


def test_names_give_camera_name_topic_and_frame():
    names = FrameNames.of(["LEFT-01", "RIGHT-01"], ["imu"], {"RIGHT-01": "front/right_optical_frame"})
    assert (
        names.frame("LEFT-01") == "left_01_optical_frame" and names.topic("LEFT-01") == "/left_01/image_raw"
    )
    assert (
        names.camera_name("RIGHT-01") == "front_right" and names.topic("RIGHT-01") == "/front/right/image_raw"
    )
    assert names.frame("imu") == "imu"


def test_a_default_that_collides_with_a_mapped_name_is_refused():
    with pytest.raises(UsageError, match="LEFT-01 and left_01 would both be frame left_01_optical_frame"):
        FrameNames.of(["LEFT-01", "left_01"])
    with pytest.raises(UsageError, match="maps A twice"):
        parse_frame_map(["A=a", "A=b"], ["A", "B"])
