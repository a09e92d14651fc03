"""Robot frame names for a rig's frames: what tf, URDF, camera_info and Kalibr call each camera.

Inside calibctl a camera's frame is its serial (``LEFT-01``), which is no legal ROS name. Every robot export
names it by a ROS frame instead: the one the user maps with ``--frame SERIAL=NAME``, else the default
derived from the serial:

- lower case, every run of characters other than ``[a-z0-9_]`` becomes one ``_``, leading and trailing
  ``_`` dropped; a name that then starts with a digit gets ``cam_`` (a camera) or ``frame_`` in front;
- a camera gets ``_optical_frame`` appended (REP 103's optical frame: z forward, x right, y down):
  ``LEFT-01`` -> ``left_01_optical_frame``, ``CAM0`` -> ``cam0_optical_frame``;
- a non-camera frame (``flange``, ``imu``) keeps its cleaned name, no suffix.

A ROS name here is ``[A-Za-z][A-Za-z0-9_]*`` segments joined by ``/`` (no ``-``, no leading ``/``).
Each camera's *base* name (its frame without ``_optical_frame``) gives the camera_info ``camera_name``
(``/`` as ``_``: camera_info_manager takes ``[A-Za-z0-9_]`` only) and the image topic ``/<base>/image_raw``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from calibctl.errors import UsageError

if TYPE_CHECKING:
    from calibctl.core.extrinsics.rig_tree import RigTree

ROS_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$")
OPTICAL_SUFFIX = "_optical_frame"
NAME_RULE = "ROS names are [a-zA-Z][a-zA-Z0-9_]* segments separated by '/' (no '-', no leading '/')"


def is_ros_name(name: str) -> bool:
    return bool(ROS_NAME.match(name))


def default_frame(serial: str, camera: bool = True) -> str:
    """The frame a serial (or a non-camera frame) gets when the user maps none (module docstring)."""
    cleaned = re.sub(r"[^a-z0-9_]+", "_", serial.lower()).strip("_") or "unnamed"
    if not cleaned[0].isalpha():
        cleaned = ("cam_" if camera else "frame_") + cleaned
    return cleaned + OPTICAL_SUFFIX if camera else cleaned


def parse_frame_map(pairs: Iterable[str], known: Sequence[str]) -> dict[str, str]:
    """``SERIAL=NAME`` options -> {serial: ROS frame}. A malformed pair, an unknown serial, a serial mapped
    twice, an illegal name or one name for two serials is a UsageError (exit 2) naming it."""
    out: dict[str, str] = {}
    for pair in pairs:
        serial, sep, name = pair.partition("=")
        serial, name = serial.strip(), name.strip()
        if not sep or not serial or not name:
            raise UsageError(
                f"--frame {pair!r} is not SERIAL=NAME", "e.g. --frame LEFT-01=front_left_camera_optical_frame"
            )
        if serial not in known:
            raise UsageError(f"--frame {pair}: {serial} is not a frame of this rig ({', '.join(known)})")
        if serial in out:
            raise UsageError(
                f"--frame maps {serial} twice ({out[serial]} and {name})", "give each serial one --frame"
            )
        if not is_ros_name(name):
            raise UsageError(f"--frame {pair}: '{name}' is not a legal ROS frame name", NAME_RULE)
        out[serial] = name
    taken: dict[str, str] = {}
    for serial, name in out.items():
        if name in taken:
            raise UsageError(
                f"--frame gives {taken[name]} and {serial} the same frame {name}", "give each its own frame"
            )
        taken[name] = serial
    return out


@dataclass(frozen=True)
class FrameNames:
    """serial (or non-camera frame) -> ROS frame, for every frame of one rig."""

    frames: Mapping[str, str]

    @classmethod
    def of(
        cls, cameras: Sequence[str], others: Sequence[str] = (), mapped: Mapping[str, str] | None = None
    ) -> FrameNames:
        mapped = mapped or {}
        frames = {c: mapped.get(c) or default_frame(c, True) for c in cameras}
        frames.update({f: mapped.get(f) or default_frame(f, False) for f in others})
        seen: dict[str, str] = {}
        for serial, name in frames.items():  # a default may collide with a mapped or another default name
            if name in seen:
                raise UsageError(
                    f"{seen[name]} and {serial} would both be frame {name}",
                    f"name one of them with --frame {serial}=NAME",
                )
            seen[name] = serial
        return cls(frames)

    def frame(self, serial: str) -> str:
        return self.frames[serial]

    def base(self, serial: str) -> str:
        """The frame without ``_optical_frame``: the camera's ROS namespace."""
        name = self.frames[serial]
        return (
            name[: -len(OPTICAL_SUFFIX)] if name.endswith(OPTICAL_SUFFIX) and name != OPTICAL_SUFFIX else name
        )

    def camera_name(self, serial: str) -> str:
        return self.base(serial).replace("/", "_")

    def topic(self, serial: str) -> str:
        return f"/{self.base(serial)}/image_raw"

    def tree(self, tree: RigTree) -> RigTree:
        """``tree`` with every frame renamed (transforms unchanged)."""
        from calibctl.core.extrinsics.rig_tree import Edge, RigTree  # cv2: not for `lint FILE` start-up

        rename = self.frames.get
        return RigTree(
            rename(tree.root) or tree.root,
            tuple(
                Edge(rename(e.parent) or e.parent, rename(e.child) or e.child, e.T_parent_child, e.covariance)
                for e in tree.edges
            ),
        )
