"""Read a calibctl robot bundle with the consumers' own code, as a robot would (run by Debian's
/usr/bin/python3,
where ROS's camera_calibration_parsers, image_geometry and mrcal are installed; not by the project's venv).

    /usr/bin/python3 robot_consumers.py BUNDLE_DIR POINTS_JSON  ->  JSON on stdout

POINTS_JSON: {"root_points_m": [[x, y, z], ...]} in the root (left) camera frame. For each camera of the
manifest: what camera_calibration_parsers.readCalibration (ROS's C++ parser) read, image_geometry's
StereoCameraModel projections of the points (rectified pixels, left and right) and depth from disparity,
mrcal's projection of the points (raw pixels) and Debian OpenCV's cv2.FileStorage + cv2.projectPoints
on the stereo file (raw pixels). Absent consumers are reported as null.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def _msg(info):
    return {
        "camera_name": None,
        "width": info.width,
        "height": info.height,
        "K": list(info.K),
        "D": list(info.D),
        "R": list(info.R),
        "P": list(info.P),
        "distortion_model": info.distortion_model,
    }


def main() -> None:
    import numpy as np

    folder, points = Path(sys.argv[1]), json.loads(Path(sys.argv[2]).read_text())
    X = np.array(points["root_points_m"], dtype=np.float64)
    manifest = json.loads((folder / "manifest.json").read_text())
    left, right = manifest["stereo"]["left"], manifest["stereo"]["right"]
    members = {m["serial"]: m for m in manifest["members"]}
    out: dict = {"ros": None, "image_geometry": None, "mrcal": None, "opencv": None}
    try:
        import camera_calibration_parsers
        import image_geometry
    except ImportError:
        pass
    else:
        infos = {}
        out["ros"] = {}
        for serial, m in members.items():
            name, info = camera_calibration_parsers.readCalibration(str(folder / m["camera_info"]))
            out["ros"][serial] = dict(_msg(info), camera_name=name)
            infos[serial] = info
        stereo = image_geometry.StereoCameraModel()
        stereo.fromCameraInfo(infos[left], infos[right])
        R1 = np.array(infos[left].R).reshape(3, 3)
        rect = (R1 @ X.T).T  # points in the left rectified frame, what StereoCameraModel projects
        pairs = [stereo.project3dToPixel(tuple(p)) for p in rect]
        depth = [stereo.getZ(lp[0] - rp[0]) for lp, rp in pairs]
        out["image_geometry"] = {
            "left_px": [list(lp) for lp, _ in pairs],
            "right_px": [list(rp) for _, rp in pairs],
            "depth_m": depth,
            "rect_z_m": rect[:, 2].tolist(),
            "baseline_m": -stereo.right.Tx() / stereo.right.fx(),
        }
    try:
        import mrcal
    except ImportError:
        pass
    else:
        out["mrcal"] = {}
        for serial, m in members.items():
            if m["mrcal"] is None:
                continue
            model = mrcal.cameramodel(str(folder / m["mrcal"]))
            p_cam = mrcal.transform_point_rt(model.extrinsics_rt_fromref(), X)
            out["mrcal"][serial] = mrcal.project(p_cam, *model.intrinsics()).tolist()
    import cv2

    pair = manifest["stereo_pairs"][0]
    fs = cv2.FileStorage(str(folder / pair["opencv"]), cv2.FILE_STORAGE_READ)
    K1, D1, K2, D2 = (fs.getNode(k).mat() for k in ("K1", "D1", "K2", "D2"))
    R, T = fs.getNode("R").mat(), fs.getNode("T").mat()
    fs.release()
    raw_l = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K1, D1)[0].reshape(-1, 2)
    raw_r = cv2.projectPoints(X, cv2.Rodrigues(R)[0], T, K2, D2)[0].reshape(-1, 2)
    out["opencv"] = {
        "version": cv2.__version__,
        "left": pair["left"],
        "right": pair["right"],
        "left_px": raw_l.tolist(),
        "right_px": raw_r.tolist(),
    }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
