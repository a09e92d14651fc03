"""Seeded corner-level sessions solved with the production k1k2 model, as core.compare.Lens (shared by the
diff tests and benchmarks/bench_diff.py): the seed's focal length and k1, k2 at 640x480, 30 views tilted
20-45 deg at 0.30-0.50 m, 0.03 px corner noise per coordinate (what the detector delivers on renders,
benchmarks/results/check.md)."""

from __future__ import annotations

import numpy as np

from calibctl.core.compare.lens import Lens, lens_from_solution
from calibctl.core.intrinsics.solve import IntrinsicsSolution, solve_intrinsics
from calibctl.core.synth.corners import synthesize_session
from calibctl.core.synth.pinhole import PinholeCamera

SIZE = (640, 480)
VIEWS = 30
NOISE_PX = 0.03
_SEED_LENS = PinholeCamera.seed_reference(SIZE)
TRUE_DIST = np.array([_SEED_LENS.dist[0], _SEED_LENS.dist[1], 0.0, 0.0, 0.0])


def true_K(focal_scale: float = 1.0, dcx_px: float = 0.0) -> np.ndarray:
    K = _SEED_LENS.K.copy()
    K[0, 0] *= focal_scale
    K[1, 1] *= focal_scale
    K[0, 2] += dcx_px
    return K


def solve(
    K: np.ndarray, seed: int, model: str = "k1k2", dist: np.ndarray = TRUE_DIST, views: int = VIEWS
) -> IntrinsicsSolution:
    s = synthesize_session(
        K, dist, SIZE, views, seed, noise_px=NOISE_PX, tilt_deg=(20.0, 45.0), distance_m=(0.3, 0.5)
    )
    return solve_intrinsics(s.object_points_per_view, s.image_points_per_view, SIZE, model)


def lens(K: np.ndarray, seed: int, model: str = "k1k2") -> Lens:
    return lens_from_solution(solve(K, seed, model))
