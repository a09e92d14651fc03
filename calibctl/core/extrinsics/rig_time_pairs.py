"""Which frames of a rig's videos were taken together: frames paired by their timestamps.

Software-synchronised cameras (one video per camera, USB webcams) expose the frames of one instant a few
milliseconds apart, and one camera may drop a frame the others have, so file numbers do not pair them: times
do. Rule: every frame of every camera is one event (camera, frame index, t_s); events are taken in time order
(ties in camera order) and each group starts at the earliest event not yet grouped and takes, from every
other camera, its first event at most ``tolerance_s`` later. A group of two or more cameras is a rig frame;
an event left alone is reported unpaired with the time to the nearest frame of another camera, never
stretched into a frame. The tolerance must stay below half of every camera's shortest frame interval, so no
camera can have two frames in one group's window (``check_tolerance``).

Timestamps come from the recorder's file (``parse_timestamps``: caliscope's ``timestamps.csv``,
``sync_index,cam_id,frame_index,frame_time`` with frame_time in seconds; sync_index is not used, the times
pair the frames) or from the video container's own per-frame times.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

TIMESTAMP_COLUMNS = ("cam_id", "frame_index", "frame_time")


@dataclass(frozen=True)
class TimedFrame:
    camera: str
    index: int
    t_s: float


@dataclass(frozen=True)
class TimeGroup:
    """One rig frame: camera -> frame index, and how far apart its frames' times are (spread_s)."""

    key: int
    frames: Mapping[str, int]
    t_s: float
    spread_s: float


@dataclass(frozen=True)
class UnpairedFrame:
    """A frame no group took; ``nearest_s``: time to the closest frame of another camera (inf when none);
    ``stretch_s``: when that frame is in a rig frame, the time span that rig frame would have with this one
    in it (beyond the tolerance, or this camera has a frame there already), else None."""

    camera: str
    index: int
    t_s: float
    nearest_s: float
    stretch_s: float | None = None


@dataclass(frozen=True)
class TimePairing:
    groups: tuple[TimeGroup, ...]
    unpaired: tuple[UnpairedFrame, ...]
    tolerance_s: float


class TimestampError(ValueError):
    """A timestamps file that cannot be used; the message names the line and what is wrong."""


def shortest_interval_s(times: Sequence[float]) -> float:
    """The shortest gap between consecutive times (inf for fewer than two)."""
    ordered = sorted(times)
    return min((b - a for a, b in zip(ordered, ordered[1:], strict=False)), default=math.inf)


def check_tolerance(times: Mapping[str, Sequence[float]], tolerance_s: float) -> None:
    """ValueError unless 0 < tolerance_s < half of every camera's shortest frame interval."""
    if not (math.isfinite(tolerance_s) and tolerance_s > 0):
        raise ValueError(f"the time tolerance must be a positive number of seconds, got {tolerance_s}")
    for camera, ts in times.items():
        gap = shortest_interval_s(ts)
        if not tolerance_s < gap / 2:
            raise ValueError(
                f"a tolerance of {tolerance_s * 1e3:g} ms is not below half of camera {camera}'s shortest "
                f"frame interval ({gap * 1e3:.3g} ms): two of its frames could fall in one rig frame"
            )


def pair_by_time(times: Mapping[str, Sequence[float]], tolerance_s: float) -> TimePairing:
    """Group the cameras' frames (camera -> time of frame i, seconds) into rig frames (module docstring)."""
    check_tolerance(times, tolerance_s)
    order = {camera: n for n, camera in enumerate(times)}
    events = sorted(
        (TimedFrame(camera, i, float(t)) for camera, ts in times.items() for i, t in enumerate(ts)),
        key=lambda e: (e.t_s, order[e.camera], e.index),
    )
    taken = [False] * len(events)
    groups: list[TimeGroup] = []
    alone: list[TimedFrame] = []
    for n, first in enumerate(events):
        if taken[n]:
            continue
        members = {first.camera: (n, first)}
        for m in range(n + 1, len(events)):
            e = events[m]
            if e.t_s - first.t_s > tolerance_s:
                break
            if not taken[m] and e.camera not in members:
                members[e.camera] = (m, e)
        if len(members) < 2:
            taken[n] = True
            alone.append(first)
            continue
        for m, _ in members.values():
            taken[m] = True
        ts = [e.t_s for _, e in members.values()]
        frames = {camera: members[camera][1].index for camera in times if camera in members}
        groups.append(TimeGroup(len(groups), frames, first.t_s, max(ts) - min(ts)))
    return TimePairing(tuple(groups), tuple(_unpaired(alone, times, groups)), tolerance_s)


def _unpaired(
    alone: Sequence[TimedFrame], times: Mapping[str, Sequence[float]], groups: Sequence[TimeGroup]
) -> list[UnpairedFrame]:
    member_of = {(c, i): g for g in groups for c, i in g.frames.items()}
    out = []
    for e in alone:
        others = [
            (abs(t - e.t_s), c, i) for c, ts in times.items() if c != e.camera for i, t in enumerate(ts)
        ]
        if not others:
            out.append(UnpairedFrame(e.camera, e.index, e.t_s, math.inf))
            continue
        nearest, camera, index = min(others)
        group = member_of.get((camera, index))
        stretch = None
        if group is not None:
            spanned = [times[c][i] for c, i in group.frames.items()] + [e.t_s]
            stretch = max(spanned) - min(spanned)
        out.append(UnpairedFrame(e.camera, e.index, e.t_s, nearest, stretch))
    return out


def parse_timestamps(text: str, source: str) -> dict[str, dict[int, float]]:
    """A recorder's timestamps CSV -> camera id (as written) -> frame index -> time, seconds.

    Raises TimestampError, naming ``source`` and the line, for missing columns, a value that is not a
    number, a frame listed twice, two frames of one camera at the same time, or times that go backwards
    as the frame index grows.
    """
    reader = csv.DictReader(io.StringIO(text))
    missing = [c for c in TIMESTAMP_COLUMNS if c not in (reader.fieldnames or [])]
    if missing:
        raise TimestampError(
            f"{source} has no column {', '.join(missing)} (a timestamps file has a header "
            f"{','.join(TIMESTAMP_COLUMNS)}, one row per frame, frame_time in seconds)"
        )
    out: dict[str, dict[int, float]] = {}
    lines: dict[tuple[str, int], int] = {}
    for row in reader:
        line = reader.line_num
        camera = (row["cam_id"] or "").strip()
        try:
            index, t_s = int(row["frame_index"]), float(row["frame_time"])
        except (TypeError, ValueError):
            raise TimestampError(f"{source} line {line}: frame_index / frame_time is not a number") from None
        if not camera or index < 0 or not math.isfinite(t_s):
            raise TimestampError(
                f"{source} line {line}: needs a cam_id, a frame_index >= 0 and a finite time"
            )
        if (camera, index) in lines:
            raise TimestampError(
                f"{source} line {line}: camera {camera} frame {index} is listed twice "
                f"(first on line {lines[(camera, index)]})"
            )
        lines[(camera, index)] = line
        out.setdefault(camera, {})[index] = t_s
    for camera, frames in out.items():
        ordered = sorted(frames.items())
        for (i, a), (j, b) in zip(ordered, ordered[1:], strict=False):
            if b == a:
                raise TimestampError(
                    f"{source}: camera {camera} frames {i} and {j} have the same time {a:.6f} s (line "
                    f"{lines[(camera, i)]} and {lines[(camera, j)]}): duplicated timestamps"
                )
            if b < a:
                raise TimestampError(
                    f"{source}: camera {camera}'s time goes backwards from frame {i} ({a:.6f} s, line "
                    f"{lines[(camera, i)]}) to frame {j} ({b:.6f} s, line {lines[(camera, j)]})"
                )
    if not out:
        raise TimestampError(f"{source} lists no frame")
    return out
