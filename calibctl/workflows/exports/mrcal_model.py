"""mrcal ``.cameramodel`` text for one camera, so mrcal-show-projection-uncertainty, -diff and friends read
calibctl's intrinsics (https://mrcal.secretsauce.net/cameramodels.html).

A .cameramodel is a Python-literal dict: ``lensmodel``, ``intrinsics`` (fx, fy, cx, cy, then the
distortion in OpenCV's order), ``extrinsics`` = rt_cam_ref (Rodrigues rvec rad, then t m; maps reference
points into the camera frame: here the rig's root camera is the reference) and ``imagersize`` [W, H].
OpenCV's pinhole models map onto mrcal's LENSMODEL_OPENCV4/5/8/12 exactly (same equations, same
coefficient order). mrcal has no Kannala-Brandt (OpenCV fisheye, ROS equidistant) model, so a fisheye
camera gets no .cameramodel: ``cameramodel`` returns None and ``missing_reason`` says why.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from calibctl.core.extrinsics.rig_problem import MemberIntrinsics

LENSMODELS = {
    4: "LENSMODEL_OPENCV4",
    5: "LENSMODEL_OPENCV5",
    8: "LENSMODEL_OPENCV8",
    12: "LENSMODEL_OPENCV12",
}


def missing_reason(m: MemberIntrinsics) -> str | None:
    """Why mrcal cannot describe this camera's lens, or None when it can."""
    if m.lens == "fisheye":
        return "mrcal has no Kannala-Brandt (equidistant fisheye) lens model"
    n = int(np.asarray(m.dist_coeffs).size)
    if n not in LENSMODELS:
        return f"mrcal has no OpenCV model with {n} distortion coefficients (it has 4, 5, 8 and 12)"
    return None


def cameramodel(
    m: MemberIntrinsics,
    T_cam_ref: np.ndarray,
    comment: str,
    valid_region_px: Sequence[Sequence[float]] | None = None,
) -> str | None:
    """The .cameramodel text of ``m`` with extrinsics ``T_cam_ref`` (4, 4), metres; None when mrcal lacks the
    lens model (``missing_reason``). ``comment`` (one line) says where it came from. ``valid_region_px``: the
    hull of the corners the solve used (the artifact's ``observed_region_px``), written as mrcal's
    ``valid_intrinsics_region`` (a closed contour: its first vertex repeated last)."""
    if missing_reason(m) is not None:
        return None
    K = np.asarray(m.camera_matrix, float)
    dist = [float(v) for v in np.ravel(m.dist_coeffs)]
    rvec = cv2.Rodrigues(np.asarray(T_cam_ref, float)[:3, :3])[0].ravel()
    extrinsics = [*map(float, rvec), *map(float, np.asarray(T_cam_ref, float)[:3, 3])]

    def floats(values: list[float]) -> str:
        return ", ".join(
            repr(float(v)) for v in values
        )  # float(): numpy 2 reprs np.float64 as "np.float64(x)"

    return (
        f"# {comment}\n{{\n    'lensmodel': '{LENSMODELS[len(dist)]}',\n"
        f"    # fx, fy, cx, cy (px), then OpenCV's k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4]]]\n"
        f"    'intrinsics': [{floats([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist])}],\n"
        f"    # rt_cam_ref: Rodrigues rvec (rad) then t (m); the reference is the rig's root camera\n"
        f"    'extrinsics': [{floats(extrinsics)}],\n"
        f"    'imagersize': [{int(m.image_size[0])}, {int(m.image_size[1])}],\n{_region(valid_region_px)}}}\n"
    )


def _region(vertices: Sequence[Sequence[float]] | None) -> str:
    """mrcal's ``valid_intrinsics_region`` entry (mrcal draws it on its plots and
    ``mrcal-show-projection-uncertainty``), or nothing without a hull of at least 3 vertices."""
    if vertices is None or len(vertices) < 3:
        return ""
    closed = [*vertices, vertices[0]]
    points = ", ".join(f"[{float(u)!r}, {float(v)!r}]" for u, v in closed)
    return (
        f"    # the hull of the corners the solve used (px): where these intrinsics were measured\n"
        f"    'valid_intrinsics_region': [{points}],\n"
    )
