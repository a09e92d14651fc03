"""Error rates of the diff verdict over 30 seeded pairs of solves per case (docs/diff.md): a 0.3 % focal
change and a 1 px principal-point shift caught in >= 95 %, an unchanged camera flagged in <= 5 %."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.compare.projection_diff import projection_diff
from tests.core.compare.sessions import lens, true_K

PAIRS = 30


def _flagged(K_b: np.ndarray, seed0: int) -> int:
    return sum(
        bool(projection_diff(lens(true_K(), seed0 + i), lens(K_b, seed0 + 10_000 + i)).significant)
        for i in range(PAIRS)
    )


@pytest.mark.slow
def test_an_unchanged_camera_is_rarely_flagged() -> None:
    assert _flagged(true_K(), 1000) <= PAIRS * 0.05


@pytest.mark.slow
def test_a_0_3_percent_focal_change_is_caught() -> None:
    assert _flagged(true_K(focal_scale=1.003), 2000) >= PAIRS * 0.95


@pytest.mark.slow
def test_a_1px_principal_point_shift_is_caught() -> None:
    assert _flagged(true_K(dcx_px=1.0), 3000) >= PAIRS * 0.95
