"""Reading a camera + IMU recording: the IMU log, per-frame corner detections, the IMU noise model.

Layouts (every file read through ``bounded``; timestamps are integer nanoseconds, kept exact as int64
until one shared origin is subtracted):

- the IMU log: ``imu0/data.csv`` (ASL / EuRoC: ``#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z
  [m s^-2]``) or ``imu0.csv`` (yac: ``#ts,wx,wy,wz,ax,ay,az``): stamp, gyro x y z, accel x y z in that
  order. A header naming deg/s or g is refused naming the factor; so is a log whose magnitudes say so
  (core.imu.samples.check_units).
- the corners: ``camN/<ns>.csv``, one file per frame (yac's layout): a stamp column first, then at
  least ``kp_x, kp_y`` (pixel) and ``p_x, p_y, p_z`` (board point, metres); a file with a header only
  is a frame without a detection. Beside them the ASL ``camN/data.csv`` (``#timestamp [ns],filename``)
  may list the frames; a stamp listed twice or out of order there is refused. With a registered board
  (``--board``) every board point must be one of that board's corners.
- or the images: no corner files, the ASL ``camN/data.csv`` listing ``camN/data/<filename>``; the
  corners are detected in each image with the registered board (``--board``, a chessboard, ChArUco or
  AprilGrid); images in none of which it is found are refused (they show another board).
- the noise model: Kalibr's ``imu.yaml`` (``gyroscope_noise_density``, ``accelerometer_noise_density``,
  ``gyroscope_random_walk``, ``accelerometer_random_walk``) or yac's ``config.yaml`` ``imu0`` block
  (``sigma_g_c``, ``sigma_a_c``, ``sigma_gw_c``, ``sigma_aw_c``, ``g``).

Every refusal is an ``InputError`` (exit 2) naming the file and the fix; the core's refusals
(``ImuInputError``) are mapped with the file they came from.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibctl import bounded, files
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.imu.samples import GRAVITY_M_S2, CameraFrames, ImuInputError, ImuNoise, ImuSamples
from calibctl.errors import InputError, UsageError
from calibctl.workflows.diagnostics import diagnostics_io as dio

CORNER_COLUMNS = ("kp_x", "kp_y", "p_x", "p_y", "p_z")
KALIBR_NOISE = {
    "gyroscope_noise_density": "gyro_noise_density",
    "accelerometer_noise_density": "accel_noise_density",
    "gyroscope_random_walk": "gyro_random_walk",
    "accelerometer_random_walk": "accel_random_walk",
}
YAC_NOISE = {
    "sigma_g_c": "gyro_noise_density",
    "sigma_a_c": "accel_noise_density",
    "sigma_gw_c": "gyro_random_walk",
    "sigma_aw_c": "accel_random_walk",
}
# EuRoC's ADIS16448 (Kalibr imu.yaml of the EuRoC datasets): used when no noise file is given
DEFAULT_NOISE = ImuNoise(1.6968e-4, 2.0e-3, 1.9393e-5, 3.0e-3)
MIN_OVERLAP_SHARE = 0.5  # of the camera's span the IMU log must cover
BOARD_POINT_TOLERANCE_M = 1e-4  # a corner's board point this far from every corner of --board: another board
_DEG = re.compile(r"deg|°")
_G_UNIT = re.compile(r"\[\s*g\s*\]|\(\s*g\s*\)|_g$")


@dataclass(frozen=True)
class Recording:
    """A recording read: IMU samples and camera frames on one time origin (seconds from ``t0_ns``; a
    frame without a board has no corners and still counts, so the dropped-frames gate sees real drops),
    the files read with their sha256, and what was left out (in words)."""

    imu: ImuSamples
    frames: CameraFrames
    t0_ns: int
    inputs: list[tuple[str, Path, str]]  # (role, path, sha256)
    notes: list[str]
    imu_span_ns: tuple[int, int]  # first and last IMU stamp


def sha256_of(path: Path) -> str:
    with files.file_errors("read", path):
        return hashlib.sha256(path.read_bytes()).hexdigest()


def imu_log_path(folder: Path) -> Path:
    """``imu0/data.csv`` (ASL) or ``imu0.csv`` (yac) under ``folder``."""
    for path in (folder / "imu0" / "data.csv", folder / "imu0.csv"):
        if path.is_file():
            return path
    if (folder / "mav0" / "imu0" / "data.csv").is_file():  # EuRoC's zip unpacks to NAME/mav0/
        raise InputError(
            f"{folder}: no IMU log (imu0/data.csv or imu0.csv); EuRoC's layout keeps it in mav0/",
            f"give the recording folder {folder / 'mav0'}",
        )
    raise InputError(
        f"{folder}: no IMU log (imu0/data.csv or imu0.csv)",
        "give the recording folder (the ASL / EuRoC layout or yac's: docs/imu.md)",
    )


def _header(path: Path) -> list[str]:
    text = bounded.read_text(path, "read the IMU log")
    first = text.split("\n", 1)[0].strip()
    if not first.startswith("#") and not re.search(r"[A-Za-z]", first):
        raise InputError(
            f"{path}: no header line",
            "the first line names the columns: stamp (ns), gyro x y z (rad/s), accel x y z (m/s^2)",
        )
    return [h.strip() for h in first.split(",")]


def _stamps_ns(cells: np.ndarray, path: Path, lines: np.ndarray) -> np.ndarray:
    try:
        return np.array([int(c) for c in cells], dtype=np.int64)
    except ValueError:
        bad = next(i for i, c in enumerate(cells) if not c.strip().lstrip("-").isdigit())
        raise InputError(
            f"{path}: line {int(lines[bad])}: stamp {cells[bad]!r} is not an integer of nanoseconds",
            "write the stamps as integer nanoseconds (EuRoC / ASL), not seconds",
        ) from None


def _check_header_units(header: list[str], path: Path) -> None:
    gyro, accel = header[1:4], header[4:7]
    if any(_DEG.search(h.lower()) for h in gyro):
        raise InputError(
            f"{path}: the gyro columns are in deg/s ({', '.join(gyro)})",
            "multiply them by pi/180 and write rad/s (header [rad s^-1])",
        )
    if any(_G_UNIT.search(h.lower()) for h in accel):
        raise InputError(
            f"{path}: the accelerometer columns are in g ({', '.join(accel)})",
            f"multiply them by {GRAVITY_M_S2} and write m/s^2 (header [m s^-2])",
        )


def read_imu_log(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(stamps ns (n,) int64, gyro (n, 3), accel (n, 3)) as written; stamps strictly increasing."""
    header = _header(path)
    if len(header) < 7:
        raise InputError(
            f"{path}: {len(header)} columns, need 7 (stamp ns, gyro x y z rad/s, accel x y z m/s^2)",
            "write the IMU log as EuRoC does: #timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z",
        )
    _check_header_units(header, path)
    table = dio.read_table(path, tuple(header[1:7]), optional_text=(header[0],), what="IMU log")
    stamps = _stamps_ns(table.text[header[0]], path, table.lines)
    steps = np.diff(stamps)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(
            f"{path}: stamps do not increase at line {int(table.lines[i])} ({stamps[i]} ns after "
            f"{stamps[i - 1]} ns; {bad.size} such step(s))",
            "sort the log by stamp and drop duplicated or overlapping samples",
        )
    gyro = np.stack([table.numeric[h] for h in header[1:4]], axis=1)
    accel = np.stack([table.numeric[h] for h in header[4:7]], axis=1)
    return stamps, gyro, accel


def _corner_file(path: Path) -> tuple[np.ndarray, np.ndarray, int | None]:
    """(board points (N, 3) m, pixels (N, 2), the stamp written inside, if any)."""
    text = bounded.read_text(path, "read the corners")
    rows = [line for line in text.splitlines() if line.strip()]
    if len(rows) <= 1:  # a header only: no board in this frame
        return np.zeros((0, 3)), np.zeros((0, 2)), None
    header = [h.strip() for h in rows[0].split(",")]
    table = dio.read_table(path, CORNER_COLUMNS, optional_text=(header[0],), what="corner CSV")
    stamps = _stamps_ns(table.text[header[0]], path, table.lines) if header[0] not in CORNER_COLUMNS else None
    if stamps is not None and np.any(stamps != stamps[0]):
        raise InputError(
            f"{path}: the rows carry {np.unique(stamps).size} different stamps",
            "one file holds one frame's corners: split it by stamp",
        )
    obj = np.stack([table.numeric[c] for c in ("p_x", "p_y", "p_z")], axis=1)
    img = np.stack([table.numeric[c] for c in ("kp_x", "kp_y")], axis=1)
    return obj, img, None if stamps is None else int(stamps[0])


@dataclass(frozen=True)
class Board:
    """The registered board the corners are detected with or checked against: NAME@REV and its spec."""

    ref: str
    spec: BoardSpec
    nominal: bool = False  # its size typed, never measured: T_imu_cam's translation scales with it


def _asl_listing(folder: Path) -> list[tuple[int, str]] | None:
    """``camN/data.csv`` when present: (stamp ns, file name) per frame, checked for duplicated stamps."""
    path = folder / "data.csv"
    if not path.is_file():
        return None
    text = bounded.read_text(path, "read the camera's frame list")
    rows = [line.split(",") for line in text.splitlines()[1:] if line.strip()]
    seen: dict[str, int] = {}
    out: list[tuple[int, str]] = []
    for i, row in enumerate(rows):
        s = row[0].strip()
        if s in seen:
            raise InputError(
                f"{path}: frame stamp {s} is listed twice (data lines {seen[s] + 1} and {i + 1})",
                "drop the duplicated frame; every camera stamp must be unique and increasing",
            )
        seen[s] = i
        if not s.isdigit() or len(row) < 2:
            raise InputError(
                f"{path}: data line {i + 1} is not 'stamp_ns,filename'",
                "the ASL frame list is '#timestamp [ns],filename', one frame a line",
            )
        if out and int(s) < out[-1][0]:  # frames out of order: overlapping logs or a reset clock
            raise InputError(
                f"{path}: frame stamp {s} (data line {i + 1}) is before {out[-1][0]} (data line {i})",
                "list the frames in the order they were taken, one recording per folder",
            )
        out.append((int(s), row[1].strip()))
    return out


def _check_board_points(path: Path, obj: np.ndarray, board: Board) -> None:
    """Every board point of a corner file is one of ``board``'s corners; InputError otherwise."""
    model = board.spec.object_points()
    d = np.min(np.linalg.norm(obj[:, None, :] - model[None, :, :], axis=2), axis=1)
    if obj.size and d.max() > BOARD_POINT_TOLERANCE_M:
        p = obj[int(np.argmax(d))]
        raise InputError(
            f"{path}: board point ({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}) m is no corner of board {board.ref} "
            f"({d.max() * 1e3:.1f} mm from the nearest)",
            "name the board these corners were detected on (--board), or register it (`calibctl board add`)",
        )


def check_image_size(gray: np.ndarray, image_size: tuple[int, int], source: str) -> None:
    if (gray.shape[1], gray.shape[0]) != image_size:
        raise InputError(
            f"{source} is {gray.shape[1]}x{gray.shape[0]}, the camera's calibration is "
            f"{image_size[0]}x{image_size[1]}",
            "name the camera these images are from (--serial, --camera, --image-topic)",
        )


def board_corners(gray: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray]:
    """The registered board's corners detected in one image: (board points (N, 3) m, pixels (N, 2));
    empty when the board is not found."""
    from calibctl.core.capture.detect import detect_board

    detection, _ = detect_board(gray, board.spec)
    if detection is None:
        return np.zeros((0, 3)), np.zeros((0, 2))
    obj = board.spec.object_points()[detection.corner_ids]
    return obj, np.asarray(detection.corners_px, np.float64).reshape(-1, 2)


def read_images(
    folder: Path, listing: list[tuple[int, str]], board: Board | None, image_size: tuple[int, int]
) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], list[Path]]:
    """The ASL image layout: every listed ``camN/data/<filename>`` read (bounded) and its corners detected
    with the registered board; (stamps ns, board points, pixels, files)."""
    import cv2

    if board is None:
        raise UsageError(
            f"{folder} holds images (data.csv), not corner files: the board must be named",
            "pass --board NAME[@REV], the registered board the images show",
        )
    stamps, objs, imgs, paths = [], [], [], []
    for stamp, name in listing:
        path = folder / "data" / name
        bounded.check_size(path, "read image")
        with files.file_errors("read image", path):
            data = path.read_bytes()
        gray = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE) if data else None
        if gray is None:
            raise InputError(f"{path} is not a readable image", "remove its line from data.csv or restore it")
        check_image_size(gray, image_size, str(path))
        obj, img = board_corners(gray, board)
        objs.append(obj)
        imgs.append(img)
        stamps.append(stamp)
        paths.append(path)
    check_board_seen(objs, board, f"{folder / 'data'}")
    return np.array(stamps, np.int64), objs, imgs, paths


def check_board_seen(objs: list[np.ndarray], board: Board, where: str) -> None:
    """Refuse images in none of which ``board`` is found: they show another board (or none)."""
    if objs and not any(len(o) for o in objs):
        raise InputError(
            f"{where}: board {board.ref} is found in none of the {len(objs)} images",
            "name the board the images show with --board NAME[@REV] (`calibctl board list`)",
        )


def read_corners(
    folder: Path, board: Board | None = None
) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], list[Path]]:
    """Every ``<ns>.csv`` of a camera folder: (stamps ns, board points, pixels, files), by stamp."""
    if not folder.is_dir():
        raise InputError(f"{folder}: no such camera folder", "name the camera folder with --camera (cam0)")
    found = sorted(
        (int(p.stem), p) for p in folder.iterdir() if p.suffix.lower() == ".csv" and p.stem.isdigit()
    )
    if len(found) < 2:
        raise InputError(
            f"{folder}: {len(found)} corner files <ns>.csv",
            "export one CSV per frame named by its stamp in ns (yac's layout: docs/imu.md)",
        )
    stamps, objs, imgs, paths = [], [], [], []
    for stamp, path in found:
        obj, img, inside = _corner_file(path)
        if board is not None:
            _check_board_points(path, obj, board)
        if inside is not None and inside != stamp:
            raise InputError(
                f"{path}: the file is named {stamp} but its rows are stamped {inside}",
                "name each corner file by the stamp of its frame",
            )
        stamps.append(stamp)
        objs.append(obj)
        imgs.append(img)
        paths.append(path)
    return np.array(stamps, np.int64), objs, imgs, paths


def _number(v: object, key: str, path: Path) -> float:
    """A YAML number; also one YAML 1.1 reads as text (``1e-05``, no dot: what Kalibr's files hold)."""
    if not isinstance(v, bool) and isinstance(v, int | float | str):
        try:
            return float(v)
        except ValueError:
            pass
    raise InputError(f"{path}: {key} = {v!r} is not a number", "a density in SI units (Kalibr)")


def read_noise(path: Path | None) -> tuple[ImuNoise, str]:
    """The IMU noise model and where it came from (``DEFAULT_NOISE`` without a file)."""
    if path is None:
        return DEFAULT_NOISE, "defaults"
    data = bounded.load_file(path, "read the IMU noise file")
    if isinstance(data, dict) and isinstance(data.get("imu0"), dict):
        data, names = data["imu0"], YAC_NOISE
    else:
        names = KALIBR_NOISE
    if not isinstance(data, dict) or not all(k in data for k in names):
        raise InputError(
            f"{path}: not a Kalibr imu.yaml (needs {', '.join(KALIBR_NOISE)})",
            "write the IMU's noise densities and random walks as Kalibr's imu.yaml fields",
        )
    values = {}
    for key, field in names.items():
        values[field] = _number(data[key], key, path)
    g = _number(data.get("g", GRAVITY_M_S2), "g", path)
    try:
        return ImuNoise(**values, gravity_m_s2=g), str(path)
    except ImuInputError as exc:
        raise InputError(f"{path}: {exc}", "fix the value in the noise file") from None


def read_recording(
    folder: Path,
    camera: str,
    intrinsics: tuple[np.ndarray, np.ndarray, tuple[int, int]],
    board: Board | None = None,
) -> Recording:
    """The IMU log and one camera's corners (or images) under ``folder`` on one origin (module
    docstring); the camera's held intrinsics (K, distortion in OpenCV's order, image size) come from the
    store, ``board`` (the registered board) detects corners in images and checks the corner files'."""
    if folder.is_file() and (folder.parent / "metadata.yaml").is_file():  # a .mcap / .db3 of a ROS 2 bag
        raise InputError(
            f"{folder} is one file of the ROS 2 bag {folder.parent}",
            f"give the bag folder {folder.parent} (the one holding metadata.yaml)",
        )
    if not folder.is_dir():
        raise InputError(f"{folder}: no such recording folder", "give the folder holding imu0 and cam0")
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", camera):
        raise UsageError(f"--camera {camera!r} is not a folder name", "name it as in the recording: cam0")
    imu_path = imu_log_path(folder)
    t_imu_ns, gyro, accel = read_imu_log(imu_path)
    cam_folder = folder / camera
    listing = _asl_listing(cam_folder) if cam_folder.is_dir() else None
    corner_files = cam_folder.is_dir() and any(
        p.suffix.lower() == ".csv" and p.stem.isdigit() for p in cam_folder.iterdir()
    )
    if listing is not None and not corner_files:
        t_cam_ns, objs, imgs, paths = read_images(cam_folder, listing, board, intrinsics[2])
    else:
        t_cam_ns, objs, imgs, paths = read_corners(cam_folder, board)
    inputs = [("imu", imu_path, sha256_of(imu_path))]
    if listing is not None:
        inputs.append(("camera", cam_folder / "data.csv", sha256_of(cam_folder / "data.csv")))
    role = "corners" if corner_files or listing is None else "images"
    cam = CameraStream(str(cam_folder), t_cam_ns, objs, imgs)
    rec = assemble(ImuStream(str(imu_path), t_imu_ns, gyro, accel), cam, intrinsics, inputs)
    kept = [paths[i] for i, t in enumerate(t_cam_ns) if rec.imu_span_ns[0] <= t <= rec.imu_span_ns[1]]
    rec.inputs.append((role, cam_folder, folder_sha256(kept)))
    return rec


@dataclass(frozen=True)
class ImuStream:
    """An IMU log as read: ``source`` names it in messages; stamps ns (n,), gyro rad/s, accel m/s^2."""

    source: str
    t_ns: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray


@dataclass(frozen=True)
class CameraStream:
    """A camera's frames as read: ``source`` names them; stamps ns (F,), per frame board points and pixels
    (empty for a frame without a board)."""

    source: str
    t_ns: np.ndarray
    objs: list[np.ndarray]
    imgs: list[np.ndarray]


def assemble(
    imu_in: ImuStream,
    cam: CameraStream,
    intrinsics: tuple[np.ndarray, np.ndarray, tuple[int, int]],
    inputs: list[tuple[str, Path, str]],
) -> Recording:
    """The two streams on one origin: refused when they do not overlap, frames outside the IMU log left
    out (named), the core's checks mapped to one line naming the source."""
    t_imu_ns, t_cam_ns = imu_in.t_ns, cam.t_ns
    notes = []
    lo, hi = max(t_imu_ns[0], t_cam_ns[0]), min(t_imu_ns[-1], t_cam_ns[-1])
    span = int(t_cam_ns[-1] - t_cam_ns[0])
    if hi <= lo or (hi - lo) < MIN_OVERLAP_SHARE * span:
        raise InputError(
            f"{cam.source} and {imu_in.source} do not overlap in time (camera {t_cam_ns[0]}..{t_cam_ns[-1]} "
            f"ns, IMU {t_imu_ns[0]}..{t_imu_ns[-1]} ns)",
            "give a camera and an IMU log of one recording, both stamped in ns on one clock",
        )
    inside = (t_cam_ns >= t_imu_ns[0]) & (t_cam_ns <= t_imu_ns[-1])
    if not inside.all():
        notes.append(f"{int((~inside).sum())} frame(s) outside the IMU log left out")
    seen = [int(i) for i in np.flatnonzero(inside)]  # a frame without a board still counts as a frame
    t0 = int(min(t_imu_ns[0], t_cam_ns[0]))
    K, dist, size = intrinsics
    try:
        imu = ImuSamples((t_imu_ns - t0) * 1e-9, imu_in.gyro, imu_in.accel)
    except ImuInputError as exc:
        raise InputError(
            f"{imu_in.source}: {exc}", "fix the log as the message says, then run again"
        ) from None
    try:
        frames = CameraFrames(
            (t_cam_ns[seen] - t0) * 1e-9,
            tuple(cam.objs[i] for i in seen),
            tuple(cam.imgs[i] for i in seen),
            K,
            dist,
            size,
        )
    except ImuInputError as exc:
        raise InputError(f"{cam.source}: {exc}", "fix the camera frames as the message says") from None
    return Recording(imu, frames, t0, list(inputs), notes, (int(t_imu_ns[0]), int(t_imu_ns[-1])))


def folder_sha256(paths: list[Path]) -> str:
    """One digest for many files: sha256 of their ``NAME SHA256`` lines, sorted by name."""
    lines = sorted(f"{p.name} {sha256_of(p)}\n" for p in paths)
    return hashlib.sha256("".join(lines).encode()).hexdigest()
