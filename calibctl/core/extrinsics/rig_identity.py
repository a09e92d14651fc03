"""Rig inputs that contradict identity or rigidity: two members that are really one camera or one folder.

An operator who gives the LEFT folder for both cameras gets a rig whose "second camera" is the first:
the solve happily returns a baseline near zero (0.000 +/- 0.245 mm on the opencv-left-right left folder
given twice) or, with each member's own intrinsics frozen, a small wrong one (2.129 mm where about 83 mm
is true), lint passes, and it became the ACTIVE rig. What gives it away, cheapest first:

* ``shared_images``: the same image bytes (content sha256) under two members; no two cameras ever
  produce byte-identical photos of a board;
* ``same_corners``: the same corner coordinates (every shared corner within ``SAME_CORNERS_PX``) in
  the same frame for two members, in at least half of their shared frames: a re-encoded copy of the
  same photos (new bytes, same picture);
* ``zero_baselines``: a solved baseline statistically indistinguishable from zero (the zero vector
  inside the translation's 99.7 % confidence ellipsoid, ``CHI2_3DOF``), or below ``MIN_BASELINE_MM`` (two lens
  barrels cannot sit closer; a beam-splitter rig shares one optical centre, which a board-based rig solve
  cannot tell apart from one camera either).

Each check returns what it found (empty: nothing contradicts); ``refuse`` raises one
InconsistentDataError (exit 1, a verdict on the data) naming every finding with its numbers.
Pure numpy; no store.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics.rig_problem import RigViews
from calibctl.core.extrinsics.rig_solve import RigSolution
from calibctl.errors import InconsistentDataError

MIN_BASELINE_MM = 1.0
CHI2_3DOF = 14.16  # chi-square, 3 degrees of freedom, 99.7 %: the 3-sigma of a 3-vector
SAME_CORNERS_PX = 0.01  # detection on two real cameras never agrees this closely on every corner
SAME_FRAME_SHARE = 0.5


@dataclass(frozen=True)
class IdentityFinding:
    """One contradiction between two members ``a`` and ``b``, in words with its numbers."""

    a: str
    b: str
    message: str


def shared_images(shas_by_camera: Mapping[str, Collection[str | None]]) -> list[IdentityFinding]:
    """Pairs of members holding the same image bytes. ``shas_by_camera``: camera -> sha256 hex digests
    of the images it contributed (None entries, unreadable images, are ignored)."""
    names = list(shas_by_camera)
    sets = {n: {s for s in shas_by_camera[n] if s} for n in names}
    found = []
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            common = sets[a] & sets[b]
            if common:
                found.append(
                    IdentityFinding(
                        a,
                        b,
                        f"{a} and {b} hold {len(common)} identical image(s) (same sha256; "
                        f"{len(sets[a])} and {len(sets[b])} images)",
                    )
                )
    return found


def _same_view(va: BoardView, vb: BoardView, tol_px: float) -> bool:
    common, ia, ib = np.intersect1d(np.asarray(va.corner_ids), np.asarray(vb.corner_ids), return_indices=True)
    if common.size == 0:
        return False
    pa = np.asarray(va.corners_px, dtype=np.float64).reshape(-1, 2)[ia]
    pb = np.asarray(vb.corners_px, dtype=np.float64).reshape(-1, 2)[ib]
    return bool(np.max(np.abs(pa - pb)) <= tol_px)


def same_corners(
    views: RigViews, tol_px: float = SAME_CORNERS_PX, share: float = SAME_FRAME_SHARE
) -> list[IdentityFinding]:
    """Pairs of members whose corners coincide (every shared corner within ``tol_px`` px) in at least
    ``share`` of the frames both saw the board in."""
    found = []
    n = len(views.cameras)
    for a in range(n):
        for b in range(a + 1, n):
            both = [
                (va, vb) for row in views.views if (va := row[a]) is not None and (vb := row[b]) is not None
            ]
            same = sum(1 for va, vb in both if _same_view(va, vb, tol_px))
            if both and same >= max(1, share * len(both)):
                found.append(
                    IdentityFinding(
                        views.cameras[a],
                        views.cameras[b],
                        f"{views.cameras[a]} and {views.cameras[b]} see the board at the same "
                        f"pixels (every corner within {tol_px:g} px) in {same} of {len(both)} "
                        "shared frames",
                    )
                )
    return found


def zero_baselines(
    pairs: Sequence[tuple[str, str, np.ndarray, np.ndarray]],
    floor_mm: float = MIN_BASELINE_MM,
    chi2_limit: float = CHI2_3DOF,
) -> list[IdentityFinding]:
    """Pairs whose translation cannot be told from zero. ``pairs``: (a, b, t_mm (3,), cov_t_mm2 (3, 3)),
    the translation of T_a_b or T_b_a in mm with its covariance. Refused: |t| below ``floor_mm``, or
    t^T cov^-1 t below ``chi2_limit`` (zero is inside the 99.7 % ellipsoid: the norm of a zero baseline
    solved with noise is biased away from zero, so |t| / sigma along t alone would pass it)."""
    found = []
    for a, b, t_mm, cov_mm2 in pairs:
        t = np.asarray(t_mm, dtype=np.float64).reshape(3)
        cov = np.asarray(cov_mm2, dtype=np.float64).reshape(3, 3)
        norm = float(np.linalg.norm(t))
        if not np.all(np.isfinite(t)):
            found.append(IdentityFinding(a, b, f"{a}-{b} baseline is not a number ({norm})"))
            continue
        d2 = float(t @ np.linalg.pinv(cov) @ t) if np.all(np.isfinite(cov)) and np.any(cov) else float("inf")
        sigma = float(np.sqrt(t @ cov @ t) / norm) if norm > 0 and np.all(np.isfinite(cov)) else float("nan")
        if d2 < chi2_limit or norm < floor_mm:
            why = (
                f"indistinguishable from zero (Mahalanobis {np.sqrt(d2):.2f} < {np.sqrt(chi2_limit):.2f})"
                if d2 < chi2_limit
                else f"below the {floor_mm:g} mm floor"
            )
            found.append(IdentityFinding(a, b, f"{a}-{b} baseline {norm:.3f} +/- {sigma:.3f} mm is {why}"))
    return found


def pair_translations(solution: RigSolution) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """Every camera pair (a < b) of a solved rig as ``zero_baselines`` reads it: T_b_a's translation in
    mm and its (3, 3) covariance in mm^2 (the joint solve's, cross terms included)."""
    names = solution.views.cameras
    out = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            out.append(
                (
                    names[a],
                    names[b],
                    solution.T_a_b(b, a)[:3, 3] * 1e3,
                    solution.pair_covariance(b, a)[3:, 3:] * 1e6,
                )
            )
    return out


def refuse(findings: Sequence[IdentityFinding], what: str) -> None:
    """Raise one InconsistentDataError naming every finding; nothing when ``findings`` is empty."""
    if not findings:
        return
    raise InconsistentDataError(
        f"{what}: the members are not distinct cameras: " + "; ".join(f.message for f in findings),
        "give each camera its own photos (was the same folder given twice, or a folder copied?); "
        "nothing was stored",
    )
