"""Honest one-sigma: over many seeds the errors of the six extrinsic components and td, divided by the
reported sigmas, have mean ~0 and sd ~1 (the issue's bar: mean within +/-0.3, sd 0.7-1.4).

60 seeds, not 30: a mean over 30 unit z-scores has a standard error of 0.18, so seven components all
inside +/-0.3 happen only about half the time even for a perfect estimator; over 60 (standard error
0.13) about nine times in ten. Measured (seeds 100-159): means -0.24..+0.11, sd 0.88-1.08; noise-free
renders leave a rotation bias of about -0.15 sigma on one axis (benchmarks/results/imu.md)."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.imu.solve import SolveOptions, solve_imu_camera
from calibctl.core.synth.imu import synthesize_imu_camera
from tests.core.imu.conftest import as_inputs
from tests.core.imu.test_solve import z_scores


def _z(seeds: range) -> np.ndarray:
    out = []
    for seed in seeds:
        rec = synthesize_imu_camera(
            100 + seed, motion="dance", duration_s=4.0, td_s=0.004 * (seed % 7) - 0.01
        )
        s = solve_imu_camera(*as_inputs(rec), SolveOptions(folds=0))
        out.append(z_scores(s, rec.truth))
    return np.array(out)


def test_z_scores_are_sane_on_a_few_seeds() -> None:
    z = _z(range(4))
    assert np.all(np.abs(z) < 4.5)
    assert 0.4 < float(np.std(z)) < 1.8


@pytest.mark.slow
def test_z_scores_have_unit_spread_over_60_seeds() -> None:
    z = _z(range(60))
    mean, sd = z.mean(axis=0), z.std(axis=0, ddof=1)
    assert np.all(np.abs(mean) <= 0.3), mean
    assert np.all((sd >= 0.7) & (sd <= 1.4)), sd
