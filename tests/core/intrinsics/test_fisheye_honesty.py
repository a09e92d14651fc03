"""Fisheye sigma over 300 seeded fisheye sessions: z = (estimate - truth) / sigma (the issue's bar), and the
solve's own bias measured with antithetic noise.

Sessions as benchmarks/bench_fisheye.py (150 / 170 / 190 deg, circular and full-frame, 15-20 views,
0.2 px), seeds 0-299. Each session is solved twice: with its noise n and with -n (same poses). In the
regime where the solve is linear in the noise, z(-n) = -z(n), so (z(n) + z(-n)) / 2 is the estimator's
bias in sigma units and whatever is left of mean z is the sampling of the noise.

Measured (2026-11-23, benchmarks/results/fisheye.md): the bias is below 0.001 sigma for every parameter (the
largest single session 0.14 sigma, cx); mean z over seeds 0-89 is -0.31 for fx, over 0-299 -0.17 and
over 0-599 -0.085 with std 0.99: the -0.31 once recorded as an expected failure was the noise of those
90 seeds (90-seed blocks range from -0.31 to +0.11), not a bias of the solve.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_fisheye import PARAMS, SIZE, flipped_noise, session, z_scores
from calibctl.core.intrinsics.solve import solve_intrinsics

MEAN_Z_MAX = 0.3  # the bar
STD_Z_RANGE = (0.7, 1.5)
BIAS_Z_MAX = 0.02  # mean of (z(n) + z(-n)) / 2; measured < 0.001 for every parameter
N_SESSIONS = 300  # mean z has a standard error of 0.058: the bar is 5 of them


@pytest.fixture(scope="module")
def z_pairs() -> tuple[np.ndarray, np.ndarray]:
    """(z with the session's noise, z with the noise negated): (N_SESSIONS, 8) each."""
    zs, twins = [], []
    for i in range(N_SESSIONS):
        cam, s = session(i)
        for corners, out in ((s.image_points_per_view, zs), (flipped_noise(s), twins)):
            sol = solve_intrinsics(s.object_points_per_view, corners, SIZE, "fisheye")
            out.append([z_scores(cam, sol)[p] for p in PARAMS])
    return np.array(zs), np.array(twins)


@pytest.mark.slow
def test_fisheye_sigma_scale_is_honest_and_fx_cx_unbiased(z_pairs):
    z, _ = z_pairs
    for k, name in enumerate(PARAMS):
        assert STD_Z_RANGE[0] <= z[:, k].std(ddof=1) <= STD_Z_RANGE[1], name
    for name in ("fx", "cx"):
        assert abs(z[:, PARAMS.index(name)].mean()) <= MEAN_Z_MAX, name


@pytest.mark.slow
def test_the_fisheye_solve_itself_has_no_bias(z_pairs):
    z, twin = z_pairs
    bias = ((z + twin) / 2).mean(axis=0)
    for k, name in enumerate(PARAMS):
        assert abs(bias[k]) <= BIAS_Z_MAX, (name, bias[k])
