"""mean_corner_motion_px (the near-duplicate rule): the whole-board shortcut gives the intersection's answer
to the bit, and every other pair of detections still goes through the intersection."""

from __future__ import annotations

import numpy as np

from calibctl.core.capture.image_outcomes import mean_corner_motion_px


def by_intersection(ids_a, px_a, ids_b, px_b) -> float | None:
    """The rule as written before the shortcut: mean displacement over the shared ids."""
    common, ia, ib = np.intersect1d(ids_a, ids_b, assume_unique=True, return_indices=True)
    return None if common.size < 4 else float(np.linalg.norm(px_a[ia] - px_b[ib], axis=1).mean())


def test_every_pair_reads_what_the_intersection_reads():
    rng = np.random.default_rng(24)
    whole = np.arange(54)
    cases = [
        (whole, whole),
        (whole[::-1].copy(), whole[::-1].copy()),
        (whole, whole[5:]),
        (whole[::2].copy(), whole),
        (whole[:3].copy(), whole[:3].copy()),
        (whole[:4].copy(), whole[:4].copy()),
        (rng.permutation(54), rng.permutation(54)),
    ]
    for ids_a, ids_b in cases:
        for _ in range(20):
            px_a = rng.uniform(0, 1280, (len(ids_a), 2))
            px_b = (
                px_a[: len(ids_b)] + rng.normal(0, 3, (len(ids_b), 2))
                if len(ids_b) <= len(ids_a)
                else rng.uniform(0, 1280, (len(ids_b), 2))
            )
            assert mean_corner_motion_px(ids_a, px_a, ids_b, px_b) == by_intersection(
                ids_a, px_a, ids_b, px_b
            )
    assert mean_corner_motion_px(whole[:3], np.zeros((3, 2)), whole[:3], np.ones((3, 2))) is None
