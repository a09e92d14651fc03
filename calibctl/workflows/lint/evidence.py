"""Does an artifact reproduce its own evidence? The identities a solve's numbers obey, checked on import.

An artifact records per-view RMS and poses, the residual bins with their corner counts, and the
covariance behind its sigmas, but not the corners (they stay in the source store's capture session), so
its reprojection cannot be recomputed. What can be recomputed from the document alone, and holds exactly
(to float rounding) for every artifact calibctl writes (measured on every model of both opencv-left-right
cameras):

* the fit RMS is OpenCV's: sqrt(sum n_i rms_i^2 / sum n_i) over the views kept, n_i the view's corners (a
  chessboard: cols x rows less the corners the corner rule removed; other boards: it lies between the
  smallest and largest view RMS); ``residual_count`` is 2 sum n_i;
* the radius and octant bins hold every fitted corner once: their count-weighted RMS is the fit RMS and
  their held-out RMS the held-out RMS; the outer-ring figures are the last radius bin's;
* the covariance is symmetric positive semi-definite, each sigma is the square root of its diagonal
  (sigma_fx = aspect_ratio x sigma_fy when fx is tied), and aspect_ratio is fx / fy;
* the principal point lies in the image, every view's board is in front of the camera, and a chessboard
  (every corner detected in every view) projects inside the image under the stated pose and lens.

Not checkable here: that the numbers fit the corners (a consistent forgery of every figure at once, or an
fx moved on a model that does not tie it, needs the capture session; import the source store's session or
re-solve). ``check_self_consistent`` (imports.py) covers the model's tied focal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from calibctl.artifacts.calibration import CalibrationArtifact, RingRms
from calibctl.workflows.board.boards import board_spec

if TYPE_CHECKING:
    from calibctl.artifacts.rig import RigCalibration

REL_TOL = 1e-6  # the document stores full doubles; its identities hold to ~1e-15
EDGE_MARGIN_PX = 2.0  # a detected corner lies in the image; its projection is off by its residual at most


def _differs(stated: float, derived: float) -> bool:
    return abs(stated - derived) > REL_TOL * max(abs(stated), abs(derived), 1e-9)


def _binned(rows: list[RingRms], held: bool) -> tuple[float | None, int]:
    """Count-weighted RMS of the bins (None when a counted bin has no figure) and the corners they hold."""
    counted = [r for r in rows if r.count > 0]
    values = [r.held_out_rms_px if held else r.fit_rms_px for r in counted]
    total = sum(r.count for r in counted)
    present = [v for v in values if v is not None]
    if total == 0 or len(present) != len(values):
        return None, total
    return math.sqrt(sum(r.count * v * v for r, v in zip(counted, present, strict=True)) / total), total


def _view_problems(art: CalibrationArtifact) -> list[str]:
    views = [v for v in art.views if not v.dropped]
    if not views:
        return []
    rms = [v.rms_px for v in views]
    problems = []
    if art.board.kind == "chessboard":
        rejected: dict[str, int] = {}
        for corner in art.rejected_corners:
            rejected[corner.view] = rejected.get(corner.view, 0) + 1
        counts = [art.board.cols * art.board.rows - rejected.get(v.name, 0) for v in views]
        corners = sum(counts)
        derived = math.sqrt(sum(n * r * r for n, r in zip(counts, rms, strict=True)) / max(corners, 1))
        if _differs(art.rms_px, derived):
            problems.append(
                f"rms_px {art.rms_px:.6g} but its {len(views)} view(s) of {corners} corners aggregate "
                f"to {derived:.6g} px"
            )
        if art.stdev.residual_count and art.stdev.residual_count != 2 * corners:
            problems.append(
                f"residual_count {art.stdev.residual_count} but its views hold {corners} corners "
                f"({2 * corners} residuals)"
            )
        for rows, name in ((art.held_out.by_radius, "radius"), (art.held_out.by_octant, "octant")):
            total = sum(r.count for r in rows)
            if total and total != corners:
                problems.append(f"its {name} bins hold {total} corners but its views {corners}")
    elif not min(rms) * (1 - REL_TOL) <= art.rms_px <= max(rms) * (1 + REL_TOL):
        problems.append(
            f"rms_px {art.rms_px:.6g} lies outside its views' RMS ({min(rms):.6g} .. {max(rms):.6g} px)"
        )
    return problems


def _bin_problems(art: CalibrationArtifact) -> list[str]:
    held = art.held_out
    problems = []
    for rows, name in ((held.by_radius, "radius"), (held.by_octant, "octant")):
        fit, _ = _binned(rows, held=False)
        if fit is not None and _differs(art.rms_px, fit):
            problems.append(f"rms_px {art.rms_px:.6g} but its {name} bins aggregate to {fit:.6g} px")
        out, _ = _binned(rows, held=True)
        if out is not None and held.rms_px is not None and _differs(held.rms_px, out):
            problems.append(
                f"held-out rms_px {held.rms_px:.6g} but its {name} bins aggregate to {out:.6g} px"
            )
    if held.by_radius and held.by_radius[-1].count > 0:
        last = held.by_radius[-1]
        for stated, binned, what in (
            (held.fit_outer_ring_rms_px, last.fit_rms_px, "fit"),
            (held.outer_ring_rms_px, last.held_out_rms_px, "held-out"),
        ):
            if stated is not None and binned is not None and _differs(stated, binned):
                problems.append(
                    f"{what} outer-ring RMS {stated:.6g} but its outer radius bin says {binned:.6g} px"
                )
    return problems


def _covariance_problems(art: CalibrationArtifact) -> list[str]:
    cov, sigma = art.stdev.covariance, art.stdev.sigma
    if cov is None:
        return []
    matrix = np.asarray(cov.matrix, dtype=np.float64)
    scale = max(float(np.abs(matrix).max()), 1e-300)
    if float(np.abs(matrix - matrix.T).max()) > 1e-9 * scale:
        return [
            "its covariance is not symmetric (largest asymmetry "
            f"{float(np.abs(matrix - matrix.T).max()):.3g})"
        ]
    problems = []
    smallest = float(np.linalg.eigvalsh(matrix).min())
    if smallest < -1e-9 * scale:
        problems.append(f"its covariance is not positive semi-definite (eigenvalue {smallest:.3g})")
    for i, name in enumerate(cov.parameters):
        if name in sigma and _differs(sigma[name], math.sqrt(max(matrix[i, i], 0.0))):
            problems.append(
                f"sigma_{name} {sigma[name]:.6g} but its covariance says "
                f"{math.sqrt(max(matrix[i, i], 0.0)):.6g}"
            )
    if cov.aspect_ratio is not None:
        fx, fy = art.camera_matrix[0][0], art.camera_matrix[1][1]
        if _differs(cov.aspect_ratio, fx / fy):
            problems.append(f"aspect_ratio {cov.aspect_ratio:.9g} but fx / fy = {fx / fy:.9g}")
        if (
            "fx" not in cov.parameters
            and "fx" in sigma
            and "fy" in sigma
            and _differs(sigma["fx"], cov.aspect_ratio * sigma["fy"])
        ):
            problems.append(
                f"sigma_fx {sigma['fx']:.6g} but aspect_ratio x sigma_fy = "
                f"{cov.aspect_ratio * sigma['fy']:.6g}"
            )
    return problems


def _geometry_problems(art: CalibrationArtifact) -> list[str]:
    width, height = art.image_size
    cx, cy = art.camera_matrix[0][2], art.camera_matrix[1][2]
    if not (0 <= cx <= width and 0 <= cy <= height):
        return [f"its principal point ({cx:.1f}, {cy:.1f}) lies outside its {width}x{height} image"]
    if art.board.kind != "chessboard" or not art.views:
        return []
    from calibctl.core.intrinsics.report_maps import (
        reprojection_residuals,  # OpenCV: only when views are checked
    )

    board_m = board_spec(art.board).object_points()
    K, dist = np.asarray(art.camera_matrix, dtype=np.float64), np.asarray(art.dist_coeffs, dtype=np.float64)
    problems = []
    for view in (v for v in art.views if not v.dropped):
        R = _rotation(view.rvec)
        depth_m = board_m @ R[2] + view.tvec_m[2]
        if float(depth_m.min()) <= 0:
            problems.append(f"view {view.name}: its board pose puts corners behind the camera")
            continue
        projected = -reprojection_residuals(
            board_m,
            np.zeros((len(board_m), 2)),
            view.rvec,
            view.tvec_m,
            K,
            dist,
            fisheye=art.model.name == "fisheye",
        )
        margin = EDGE_MARGIN_PX + 3 * (view.worst_corner_px or view.rms_px)
        outside = (
            (projected[:, 0] < -margin)
            | (projected[:, 0] > width + margin)
            | (projected[:, 1] < -margin)
            | (projected[:, 1] > height + margin)
            | ~np.isfinite(projected).all(axis=1)
        )
        if outside.any():
            problems.append(
                f"view {view.name}: {int(outside.sum())} of its board's corners project outside the "
                f"{width}x{height} image under its pose and lens, yet every corner was detected"
            )
    return problems


def _rotation(rvec: tuple[float, float, float]) -> np.ndarray:
    """Rodrigues vector (radians) -> (3, 3) rotation, R_cam_board."""
    r = np.asarray(rvec, dtype=np.float64)
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.eye(3)
    k = r / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross


def evidence_problems(art: CalibrationArtifact) -> list[str]:
    """Every identity ``art``'s own numbers break (empty: consistent as far as the document can show)."""
    return [*_view_problems(art), *_bin_problems(art), *_covariance_problems(art), *_geometry_problems(art)]


def rig_evidence_problems(cal: RigCalibration, members: Mapping[str, CalibrationArtifact]) -> list[str]:
    """Every identity a rig version's own numbers break, ``members`` the calibrations it pins (serial ->
    this store's artifact of the same version and hash): a member's copy inside the rig that the rig solve
    did not refine is that calibration's numbers (image size, lens, K, distortion); each edge's
    translation and rotation are its T_parent_child's; each pair's baseline is the tree's. (The sigmas are
    not compared: documents written by hand for tests, and older ones, carry their own.) A forgery that
    moves one number and recomputes the hash breaks one of these."""
    from calibctl.core.extrinsics.rig_tree import Edge, orient_tree  # cv2: only for a rig

    problems = []
    for m in cal.members:
        art = members.get(m.serial)
        if art is None:
            continue
        lens = "fisheye" if art.model.name == "fisheye" else "pinhole"
        if tuple(m.image_size) != tuple(art.image_size) or m.lens != lens:
            problems.append(
                f"member {m.serial}@{m.version} is a {m.image_size[0]}x{m.image_size[1]} {m.lens} camera in "
                f"the rig, {art.image_size[0]}x{art.image_size[1]} {lens} in its calibration"
            )
            continue
        if m.refined:
            continue
        K, dist = np.asarray(m.camera_matrix), np.asarray(m.dist_coeffs)
        K_art, dist_art = np.asarray(art.camera_matrix), np.asarray(art.dist_coeffs)
        n = min(len(dist), len(dist_art))
        if (
            not np.allclose(K, K_art, rtol=REL_TOL, atol=0)
            or not np.allclose(dist[:n], dist_art[:n], rtol=REL_TOL, atol=1e-12)
            or np.any(dist[n:])
            or np.any(dist_art[n:])
        ):
            problems.append(
                f"member {m.serial}@{m.version} was not refined by the rig solve, yet its K or distortion "
                f"in the rig (fx {K[0, 0]:.6g}) is not its calibration's (fx {K_art[0, 0]:.6g})"
            )
    edges = [
        Edge(e.parent, e.child, np.asarray(e.T_parent_child), np.asarray(e.covariance)) for e in cal.edges
    ]
    for stored, e in zip(cal.edges, edges, strict=True):
        for name, stated, derived in (
            ("translation_mm", stored.translation_mm, e.translation_mm),
            ("rotation_deg", stored.rotation_deg, e.rotation_deg),
        ):
            if _differs(stated, derived) and abs(stated - derived) > 1e-9:
                problems.append(
                    f"edge {e.parent} -> {e.child}: {name} {stated:.6g} but its T_parent_child says "
                    f"{derived:.6g}"
                )
    try:
        tree = orient_tree(edges, cal.root)
    except ValueError as exc:
        return [*problems, f"its edges do not form one tree under {cal.root} ({exc})"]
    serials = {m.serial for m in cal.members}
    for p in cal.pairs:
        if p.a not in serials or p.b not in serials:
            continue
        baseline_mm = float(np.linalg.norm(tree.T(p.b, p.a)[:3, 3]) * 1e3)
        if _differs(p.baseline_mm, baseline_mm) and abs(p.baseline_mm - baseline_mm) > 1e-6:
            problems.append(
                f"pair {p.a}-{p.b}: baseline_mm {p.baseline_mm:.6g} but its tree says {baseline_mm:.6g}"
            )
    return problems
