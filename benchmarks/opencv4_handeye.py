"""Helper of bench_handeye.py, run by a Python whose OpenCV still has calibrateHandEye (4.x).

OpenCV 5's wheels dropped cv2.calibrateHandEye, so the benchmark runs this file with another
interpreter (``--opencv4-python``, e.g. a throwaway venv with ``opencv-python-headless<5``). It needs
numpy and cv2 only; it reads cases from an .npz and prints JSON: per case and method the
T_gripper_cam it returned and the best in-process time of ``repeats`` calls.

    python opencv4_handeye.py CASES.npz REPEATS
"""

from __future__ import annotations

import json
import sys
import time

import cv2
import numpy as np

METHODS = {
    "TSAI": cv2.CALIB_HAND_EYE_TSAI,
    "PARK": cv2.CALIB_HAND_EYE_PARK,
    "HORAUD": cv2.CALIB_HAND_EYE_HORAUD,
    "ANDREFF": cv2.CALIB_HAND_EYE_ANDREFF,
    "DANIILIDIS": cv2.CALIB_HAND_EYE_DANIILIDIS,
}


def main() -> None:
    cases = np.load(sys.argv[1])
    repeats = int(sys.argv[2])
    names = sorted({k.rsplit("/", 1)[0] for k in cases.files})
    out = {"opencv_version": cv2.__version__, "numpy_version": np.__version__, "cases": {}}
    for name in names:
        args = [
            list(cases[f"{name}/{k}"])
            for k in ("R_gripper2base", "t_gripper2base", "R_target2cam", "t_target2cam")
        ]
        per = {}
        for method, flag in METHODS.items():
            best = float("inf")
            for _ in range(repeats):
                start = time.perf_counter()
                R, t = cv2.calibrateHandEye(*args, method=flag)
                best = min(best, time.perf_counter() - start)
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, np.asarray(t).reshape(3)
            per[method] = {"T_gripper_cam": T.tolist(), "best_s": best}
        out["cases"][name] = per
    print(json.dumps(out))


if __name__ == "__main__":
    main()
