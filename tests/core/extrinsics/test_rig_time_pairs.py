"""Frames of a rig's videos paired by time: offsets of a few ms pair, a frame beyond the tolerance is
reported with its distance, never stretched into a frame; a timestamps file that cannot be used is refused."""

from __future__ import annotations

import math

import pytest

from calibctl.core.extrinsics.rig_time_pairs import TimestampError, pair_by_time, parse_timestamps

PERIOD_S = 1 / 6  # caliscope's webcams ran at 6 fps


def _times(offset_ms: float, n: int = 5) -> list[float]:
    return [123.0 + i * PERIOD_S + offset_ms / 1e3 for i in range(n)]


def test_frames_a_few_ms_apart_pair_up_in_order():
    pairing = pair_by_time({"A": _times(0.0), "B": _times(1.5), "C": _times(4.0)}, 0.005)
    assert [dict(g.frames) for g in pairing.groups] == [{"A": i, "B": i, "C": i} for i in range(5)]
    assert all(math.isclose(g.spread_s, 0.004, abs_tol=1e-9) for g in pairing.groups)
    assert pairing.unpaired == ()


def test_a_frame_outside_the_tolerance_is_reported_with_its_distance_not_paired():
    late = _times(2.0)
    late[3] += 0.010  # 12 ms after A's frame 3
    pairing = pair_by_time({"A": _times(0.0), "B": late}, 0.005)
    assert [g.frames["A"] for g in pairing.groups] == [0, 1, 2, 4]
    assert [(u.camera, u.index) for u in pairing.unpaired] == [("A", 3), ("B", 3)]
    assert math.isclose(pairing.unpaired[0].nearest_s, 0.012, abs_tol=1e-9)


def test_a_frame_near_a_rig_frame_it_would_stretch_beyond_the_tolerance_says_so():
    # C is 1.5 ms from B but 5.5 ms from A, which started the rig frame: C's frame would spread it to 5.5 ms
    pairing = pair_by_time({"A": _times(0.0), "B": _times(4.0), "C": _times(5.5)}, 0.005)
    assert dict(pairing.groups[0].frames) == {"A": 0, "B": 0}
    late = pairing.unpaired[0]
    assert (late.camera, late.index) == ("C", 0)
    assert math.isclose(late.nearest_s, 0.0015, abs_tol=1e-9)
    assert late.stretch_s is not None and math.isclose(late.stretch_s, 0.0055, abs_tol=1e-9)


def test_a_dropped_frame_leaves_the_others_paired():
    pairing = pair_by_time(
        {"A": _times(0.0), "B": _times(1.0)[:2] + _times(1.0)[3:], "C": _times(3.0)}, 0.005
    )
    assert dict(pairing.groups[2].frames) == {"A": 2, "C": 2}
    assert dict(pairing.groups[3].frames) == {"A": 3, "B": 2, "C": 3}


def test_a_tolerance_of_half_a_frame_interval_or_more_is_refused():
    with pytest.raises(ValueError, match="not below half of camera A's shortest frame interval"):
        pair_by_time({"A": _times(0.0), "B": _times(1.0)}, PERIOD_S / 2)
    with pytest.raises(ValueError, match="positive"):
        pair_by_time({"A": _times(0.0), "B": _times(1.0)}, 0.0)


CSV_HEAD = "sync_index,cam_id,frame_index,frame_time\n"


def test_the_recorders_file_reads_per_camera_frame_times():
    text = CSV_HEAD + "26,1,26,123.3348\n26,0,26,123.3379\n27,0,27,123.5018\n"
    assert parse_timestamps(text, "ts.csv") == {"1": {26: 123.3348}, "0": {26: 123.3379, 27: 123.5018}}


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            "0,0,0,1.0\n1,0,1,1.0\n",
            "ts.csv: camera 0 frames 0 and 1 have the same time 1.000000 s (line 2 and 3)",
        ),
        ("0,0,0,1.0\n0,0,0,1.1\n", "ts.csv line 3: camera 0 frame 0 is listed twice (first on line 2)"),
        ("0,0,0,1.0\n1,0,1,0.9\n", "camera 0's time goes backwards from frame 0"),
        ("0,0,x,1.0\n", "ts.csv line 2: frame_index / frame_time is not a number"),
        ("", "ts.csv lists no frame"),
    ],
)
def test_a_timestamps_file_that_cannot_be_used_is_refused_naming_the_line(body, message):
    with pytest.raises(TimestampError) as info:
        parse_timestamps(CSV_HEAD + body, "ts.csv")
    assert message in str(info.value)


def test_a_file_without_the_columns_says_which():
    with pytest.raises(TimestampError, match="ts.csv has no column frame_time"):
        parse_timestamps("cam_id,frame_index\n0,1\n", "ts.csv")
