"""The plain OpenCV stereo calibration a user would write, as the reference calibctl's rig solve is
benchmarked against (benchmarks/bench_rig.py): findChessboardCorners (ADAPTIVE_THRESH |
NORMALIZE_IMAGE) + cornerSubPix 11x11 on every photo, cv2.calibrateCamera per camera on all its
detections (flags 0), cv2.stereoCalibrate with CALIB_FIX_INTRINSIC on the pairs both detected.

    python benchmarks/plain_stereo.py LEFT_DIR RIGHT_DIR COLS ROWS SQUARE_M
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

import cv2
import numpy as np

CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)


def _key(path: Path) -> int:
    return int(re.findall(r"\d+", path.stem)[-1])


def detect(path: Path, pattern: tuple[int, int]) -> tuple[np.ndarray | None, tuple[int, int]]:
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    ok, corners = cv2.findChessboardCorners(
        gray, pattern, cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    )
    size = (gray.shape[1], gray.shape[0])
    if not ok:
        return None, size
    return cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), CRITERIA).reshape(-1, 2), size


def plain_stereo(left: Path, right: Path, cols: int, rows: int, square_m: float) -> dict[str, float]:
    """Baseline (m), rotation (deg), stereo RMS, epipolar RMS (px, fitted pairs) and wall time (s)."""
    start = time.perf_counter()
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    found: list[dict[int, np.ndarray]] = []
    sizes = []
    Ks, Ds = [], []
    for folder in (left, right):
        det = {}
        for p in sorted(folder.iterdir()):
            corners, size = detect(p, (cols, rows))
            if corners is not None:
                det[_key(p)] = corners
        sizes.append(size)
        _, K, D, _, _ = cv2.calibrateCamera([obj] * len(det), list(det.values()), size, None, None)
        found.append(det)
        Ks.append(K)
        Ds.append(D)
    keys = sorted(set(found[0]) & set(found[1]))
    rms, _, _, _, _, R, T, E, F = cv2.stereoCalibrate(
        [obj] * len(keys),
        [found[0][k] for k in keys],
        [found[1][k] for k in keys],
        Ks[0],
        Ds[0],
        Ks[1],
        Ds[1],
        sizes[0],
        flags=cv2.CALIB_FIX_INTRINSIC,
    )
    elapsed = time.perf_counter() - start
    d = []
    for k in keys:
        a = cv2.undistortPoints(found[0][k].reshape(-1, 1, 2), Ks[0], Ds[0], P=Ks[0]).reshape(-1, 2)
        b = cv2.undistortPoints(found[1][k].reshape(-1, 1, 2), Ks[1], Ds[1], P=Ks[1]).reshape(-1, 2)
        la = cv2.computeCorrespondEpilines(a.reshape(-1, 1, 2), 1, F).reshape(-1, 3)
        lb = cv2.computeCorrespondEpilines(b.reshape(-1, 1, 2), 2, F).reshape(-1, 3)
        d += list(np.abs(np.sum(la[:, :2] * b, axis=1) + la[:, 2]))
        d += list(np.abs(np.sum(lb[:, :2] * a, axis=1) + lb[:, 2]))
    return {
        "pairs": len(keys),
        "left": len(found[0]),
        "right": len(found[1]),
        "baseline_m": float(np.linalg.norm(T)),
        "rotation_deg": float(np.rad2deg(np.linalg.norm(cv2.Rodrigues(R)[0]))),
        "stereo_rms_px": float(rms),
        "epipolar_rms_px": float(np.sqrt(np.mean(np.square(d)))),
        "time_s": elapsed,
    }


if __name__ == "__main__":
    l_dir, r_dir, c, r, s = sys.argv[1:6]
    print(plain_stereo(Path(l_dir), Path(r_dir), int(c), int(r), float(s)))
