"""``calibctl imu synth``: a rendered camera + IMU recording with known T_imu_cam and td (tests, demos).

Writes the layout ``imu solve`` reads (``recording``): ``imu0/data.csv`` (EuRoC's header and units:
ns, rad/s, m/s^2), ``cam0/<ns>.csv`` (one file per frame: stamp, pixel, board point in metres) or, with
``images``, the ASL image layout ``cam0/data.csv`` + ``cam0/data/<ns>.png`` (the board, a 7 x 6
inner-corner chessboard of 50 mm squares, or with ``pattern`` aprilgrid Kalibr's AprilGrid of 6 x 5 tags
of 55 mm, spacing 0.3, its centre where the chessboard's is, rendered from each frame's pose, the camera
1 m from it),
Kalibr's ``imu.yaml`` with the noise densities rendered, and ``truth.json`` (T_imu_cam, td_s, biases,
gravity, the intrinsics rendered with, Kalibr's T_cam_imu and timeshift_cam_imu). The recording comes
from core.synth.imu; with ``serial`` it is rendered through that camera's active stored calibration,
so ``imu solve --serial`` holds the very intrinsics that made it. With ``stereo`` a second camera of
the rig (EuRoC's stereo pair: 11 cm along the first camera's x, the same lens and clock) writes its
corner files to ``cam1/`` and its T_imu_cam to ``truth.json``'s ``more_cameras``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from calibctl.config import Settings
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.extrinsics import se3
from calibctl.core.synth.imu import (
    EUROC_LIKE_T_CAM0_CAM1,
    EUROC_LIKE_T_IMU_CAM,
    ImuCameraRecording,
    grid_points,
    synthesize_imu_camera,
)
from calibctl.errors import AlreadyExistsError, UsageError
from calibctl.files import file_errors, write_atomic
from calibctl.workflows.imu.imu_solve import camera_intrinsics

EPOCH_NS = 1_600_000_000_000_000_000  # the recording's first stamps sit near this (any clock would do)
IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
CORNER_HEADER = "#timestamp [ns],kp_x,kp_y,p_x,p_y,p_z,corner_id"
IMAGE_BOARD = BoardSpec.chessboard(7, 6, 0.05)  # the render's board points (core.synth.imu.grid_points)
# about the chessboard's printed size (412 x 341 mm): a Kalibr user's target, detected with AprilTag 36h11
IMAGE_BOARDS = {"chessboard": IMAGE_BOARD, "aprilgrid": BoardSpec.aprilgrid(6, 5, 0.055, 0.3)}
IMAGE_DISTANCE_M = 1.0  # the whole printed board stays in view
GYRO_RANDOM_WALK = 1e-5  # written to imu.yaml: the render's biases are constant
ACCEL_RANDOM_WALK = 1e-4


def _ns(t_s: np.ndarray) -> np.ndarray:
    return EPOCH_NS + np.round(np.asarray(t_s) * 1e9).astype(np.int64)


def _board_in_grid(board: BoardSpec) -> np.ndarray:
    """T_grid_board (4, 4): where ``board`` sits in the rendered grid's frame. The chessboard is the grid;
    another board is centred on it and turned half a turn about x, so its printed face, not its back,
    faces the camera (the render looks along the grid's -z; a mirrored AprilTag reads as no tag)."""
    if board == IMAGE_BOARD:
        return np.eye(4)
    R = np.diag([1.0, -1.0, -1.0])
    return se3.transform(R, IMAGE_BOARD.object_points().mean(axis=0) - R @ board.object_points().mean(axis=0))


def _write_images(
    out: Path, rec: ImuCameraRecording, stamps: np.ndarray, seed: int, force: bool, board: BoardSpec
) -> None:
    """Each frame's ``board`` rendered at the pose its corners give (PnP through the rendered lens), placed
    on the rendered grid by ``_board_in_grid`` (the board frame is the solve's to choose: only gravity lives
    in it, and truth.json turns it with the board)."""
    import cv2

    from calibctl.core.synth.pinhole import PinholeCamera, render_view

    dist = np.zeros(5)
    dist[: min(5, rec.dist_coeffs.size)] = rec.dist_coeffs[:5]
    camera = PinholeCamera(np.asarray(rec.camera_matrix, np.float64), dist, rec.image_size)
    rng = np.random.default_rng(seed + 7_000_003)
    with file_errors("create", out / "cam0" / "data"):
        (out / "cam0" / "data").mkdir(parents=True, exist_ok=True)
    rows = ["#timestamp [ns],filename"]
    T_grid_board = _board_in_grid(board)
    for t, obj, img in zip(stamps, rec.object_points, rec.image_points, strict=True):
        ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist)
        if not ok:
            continue
        T = se3.transform(se3.rotation_from_rotvec(rvec.ravel()), tvec.ravel()) @ T_grid_board
        ok, png = cv2.imencode(".png", render_view(camera, board, T, rng, supersample=2))
        write_atomic(out / "cam0" / "data" / f"{t}.png", png.tobytes(), force=force)
        rows.append(f"{t},{t}.png")
    write_atomic(out / "cam0" / "data.csv", "\n".join(rows) + "\n", force=force)


def _board_truth(pattern: str) -> dict[str, Any]:
    """truth.json's board: what ``board add`` takes (an AprilGrid also as Kalibr's target.yaml fields)."""
    if pattern == "chessboard":
        return {"kind": "chessboard", "cols": 7, "rows": 6, "square_mm": 50.0}
    b = IMAGE_BOARDS[pattern]
    cols, rows = b.tags
    return {"kind": "aprilgrid", "target_type": "aprilgrid", "tagCols": cols, "tagRows": rows,
            "tagSize": b.square_size_m, "tagSpacing": b.tag_spacing}  # fmt: skip


def run_imu_synth(
    settings: Settings,
    out: Path,
    seed: int = 0,
    *,
    motion: str = "dance",
    duration_s: float = 6.0,
    td_s: float = 0.012,
    line_delay_s: float = 0.0,
    serial: str | None = None,
    images: bool = False,
    pattern: str = "chessboard",
    stereo: bool = False,
    force: bool = False,
) -> dict[str, Any]:
    """Render and write the recording (module docstring); AlreadyExistsError when ``out`` holds one."""
    truth_path = out / "truth.json"
    if truth_path.exists() and not force:
        raise AlreadyExistsError(f"{out} already holds a rendered recording", "pass --force to overwrite it")
    if motion not in ("dance", "corridor"):
        raise UsageError(f"--motion {motion!r} is not dance or corridor")
    if not 1.0 <= duration_s <= 600.0:
        raise UsageError(f"--duration-s {duration_s:g} is outside 1..600 s")
    lens: dict[str, Any] = {}
    camera = None
    if serial is not None:
        camera, (K, dist, size) = camera_intrinsics(settings, serial)
        lens = {"camera_matrix": K, "dist_coeffs": dist, "image_size": size}
    if pattern not in IMAGE_BOARDS:
        raise UsageError(f"--pattern {pattern!r} is not {' or '.join(IMAGE_BOARDS)}")
    if pattern != "chessboard" and not images:
        raise UsageError(
            "--pattern draws the board of --images; corner files carry no pattern", "add --images"
        )
    if stereo and images:
        raise UsageError("--stereo writes corner files", "drop --images, or --stereo")
    if stereo:
        lens["more_cameras"] = (EUROC_LIKE_T_IMU_CAM @ EUROC_LIKE_T_CAM0_CAM1,)
    if images:
        lens["distance_m"] = IMAGE_DISTANCE_M
        assert np.allclose(grid_points(), IMAGE_BOARD.object_points())
    rec = synthesize_imu_camera(
        seed, motion=motion, duration_s=duration_s, td_s=td_s, line_delay_s=line_delay_s, **lens
    )
    t_imu, t_cam = _ns(rec.imu_t_s), _ns(rec.cam_t_s)
    rows = [IMU_HEADER] + [
        f"{t},{w[0]:.9f},{w[1]:.9f},{w[2]:.9f},{a[0]:.9f},{a[1]:.9f},{a[2]:.9f}"
        for t, w, a in zip(t_imu, rec.gyro_rad_s, rec.accel_m_s2, strict=True)
    ]
    for d in ("imu0", "cam0"):
        with file_errors("create", out / d):
            (out / d).mkdir(parents=True, exist_ok=True)
    write_atomic(out / "imu0" / "data.csv", "\n".join(rows) + "\n", force=force)
    if images:
        _write_images(out, rec, t_cam, seed, force, IMAGE_BOARDS[pattern])
    cameras = [("cam0", rec.object_points, rec.image_points)] + [
        (f"cam{k + 1}", more.object_points, more.image_points) for k, more in enumerate(rec.more_cameras)
    ]
    for folder, objs, imgs in [] if images else cameras:
        with file_errors("create", out / folder):
            (out / folder).mkdir(parents=True, exist_ok=True)
        for t, obj, img in zip(t_cam, objs, imgs, strict=True):
            lines = [CORNER_HEADER] + [
                f"{t},{u:.6f},{v:.6f},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f},{i}"
                for i, ((u, v), p) in enumerate(zip(img, obj, strict=True))
            ]
            write_atomic(out / folder / f"{t}.csv", "\n".join(lines) + "\n", force=force)
    tr = rec.truth
    noise = {
        "gyroscope_noise_density": float(tr.gyro_noise_density),
        "accelerometer_noise_density": float(tr.accel_noise_density),
        "gyroscope_random_walk": GYRO_RANDOM_WALK,
        "accelerometer_random_walk": ACCEL_RANDOM_WALK,
        "rostopic": "/imu0",
        "update_rate": round(1.0 / float(np.median(np.diff(rec.imu_t_s))), 1),
    }  # dumped by yaml: 1e-05 written by hand is a string to Kalibr's yaml.safe_load, 1.0e-05 a float
    write_atomic(
        out / "imu.yaml",
        "# Kalibr imu.yaml: the noise calibctl imu synth rendered\n" + yaml.safe_dump(noise, sort_keys=False),
        force=True,
    )
    truth = {
        "T_imu_cam": tr.T_imu_cam.tolist(),
        "td_s": tr.td_s,
        "td_convention": "t_imu = t_cam + td_s",
        "T_cam_imu": se3.invert(tr.T_imu_cam).tolist(),
        "timeshift_cam_imu": tr.td_s,
        "line_delay_s": tr.line_delay_s,
        "gyro_bias_rad_s": tr.gyro_bias_rad_s.tolist(),
        "accel_bias_m_s2": tr.accel_bias_m_s2.tolist(),
        "gravity_board_m_s2": (
            _board_in_grid(IMAGE_BOARDS[pattern])[:3, :3].T @ tr.gravity_w_m_s2
            if images
            else tr.gravity_w_m_s2
        ).tolist(),
        "noise_px": tr.noise_px,
        "camera": camera,
        "camera_matrix": np.asarray(rec.camera_matrix).tolist(),
        "dist_coeffs": np.asarray(rec.dist_coeffs).tolist(),
        "image_size": list(rec.image_size),
        "motion": motion,
        "board": _board_truth(pattern) if images else None,
        "duration_s": duration_s,
        "seed": seed,
        "frames": int(t_cam.size),
        "imu_samples": int(t_imu.size),
        "more_cameras": [
            {"folder": f"cam{k + 1}", "T_imu_cam": more.T_imu_cam.tolist()}
            for k, more in enumerate(rec.more_cameras)
        ],
    }
    write_atomic(truth_path, json.dumps(truth, indent=2) + "\n", force=True)
    return {
        "out": str(out),
        "frames": truth["frames"],
        "imu_samples": truth["imu_samples"],
        "motion": motion,
        "seed": seed,
        "td_s": tr.td_s,
        "camera": camera,
        "truth": str(truth_path),
    }
