"""core.extrinsics.rig_identity: two members that are one camera (same bytes, same pixels, no baseline)."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics.rig_identity import (
    MIN_BASELINE_MM,
    refuse,
    same_corners,
    shared_images,
    zero_baselines,
)
from calibctl.core.extrinsics.rig_problem import RigViews
from calibctl.errors import InconsistentDataError


def test_shared_images_names_the_pair_and_the_count():
    found = shared_images({"L": ["a", "b", None], "R": ["b", "c", None], "M": ["d"]})
    assert [(f.a, f.b) for f in found] == [("L", "R")]
    assert "1 identical image(s)" in found[0].message
    assert shared_images({"L": ["a"], "R": ["b"]}) == []
    assert shared_images({"L": [None], "R": [None]}) == []  # unreadable images share no content


def _views(offset_px: float, frames: int = 4, copied: int = 4) -> RigViews:
    rng = np.random.default_rng(0)
    ids = np.arange(12)
    rows = []
    for f in range(frames):
        pts = rng.uniform(50, 600, size=(12, 2))
        right = pts + (offset_px if f < copied else 40.0)
        rows.append((BoardView(f"l{f}", ids, pts), BoardView(f"r{f}", ids, right), None))
    return RigViews(("L", "R", "X"), np.zeros((12, 3)), tuple(str(f) for f in range(frames)), tuple(rows))


def test_same_corners_in_most_frames_is_one_camera_and_a_real_offset_is_not():
    assert [(f.a, f.b) for f in same_corners(_views(0.0))] == [("L", "R")]
    assert "in 4 of 4 shared frames" in same_corners(_views(0.004))[0].message
    assert same_corners(_views(0.05)) == []  # a re-detected second camera never agrees this closely
    assert same_corners(_views(0.0, frames=5, copied=2)) == []  # 2 of 5: not the majority
    assert len(same_corners(_views(0.0, frames=4, copied=2))) == 1  # half is enough


def _pair(t_mm, sigma_mm):
    return ("L", "R", np.asarray(t_mm, dtype=float), np.eye(3) * sigma_mm**2)


@pytest.mark.parametrize(
    ("t_mm", "sigma", "words"),
    [
        ([0.0, 0.0, 0.0], 0.245, "indistinguishable from zero (Mahalanobis 0.00 < 3.76)"),
        (
            [1.2, 1.2, 0.3],
            0.63,
            "indistinguishable from zero",
        ),  # |t| 1.7 = 2.7 sigma along t: biased norm of noise
        ([0.5, 0.0, 0.0], 0.01, f"below the {MIN_BASELINE_MM:g} mm floor"),
        ([float("nan"), 0.0, 0.0], 0.1, "not a number"),
    ],
)
def test_zero_baselines_refused(t_mm, sigma, words):
    found = zero_baselines([_pair(t_mm, sigma)])
    assert len(found) == 1 and words in found[0].message, found


def test_real_baselines_pass():
    assert (
        zero_baselines(
            [_pair([75.0, 0.1, 0.0], 0.3), _pair([2.0, 0.0, 0.0], 0.1), _pair([0.0, 4.0, 0.0], float("nan"))]
        )
        == []
    )


def test_refuse_is_a_verdict_naming_every_finding():
    refuse([], "nothing")  # no finding, no error
    with pytest.raises(
        InconsistentDataError,
        match="rig R1 capture: the members are not distinct cameras: .*L-R baseline 0.500 \\+/- 0.010 mm",
    ) as info:
        refuse(zero_baselines([_pair([0.5, 0, 0], 0.01)]), "rig R1 capture")
    assert info.value.exit_code == 1 and "nothing was stored" in (info.value.hint or "")
