"""``calibctl imu solve`` as one workflow call: target checked, recording read, solve and gates, the rig's
next version (``--rig``), the result file (``-o``); the CLI parses, calls ``run_imu`` and renders.

Order: with ``--rig`` the target is refused before anything is read (exit 2, nothing stored:
``edges.versions.check_sensor_target``); the camera's active stored calibration gives the held
intrinsics (``--serial``; a camera without one is exit 2); the recording is read (``recording``); the
core solves and gates it (``core.imu.calibrate``: on a (td, rotation) correlation it cannot resolve it
holds td at ``--hold-td-ms`` when given, else refuses); the typed result becomes the edge's evidence at
full precision (``evidence``) and is stored as the rig's next version through the ``edges`` room, a
rejected result as a rejected version (never active). ``result_json`` is the one rounded JSON shape
that ``--json`` prints and ``-o`` writes (sealed: ``kind``, ``content_sha256`` and, with a signing key,
its ``signature``, as ``lidar solve -o``; ``calibctl lint FILE`` checks them).

Several cameras (``ImuRequest.more``: further (camera folder, serial) pairs) are solved in one joint
solve against one IMU trajectory, gravity and biases (``core.imu.calibrate.calibrate_cameras``); each
camera keeps its own outcome, edge ``imu_frame -> serial`` and stored version (in the order given), and
the first camera's outcome carries the others in ``others``. With ``--rig``, a further camera that the
rig's active tree already relates to the first (not through the IMU frame) is held through that pose
(``held_by_rig``): its corners pin the first camera's extrinsic, and it gets no edge of its own (the
tree already gives its T_imu_cam).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from calibctl.artifacts.common import utc_now
from calibctl.artifacts.imu import (
    COVARIANCE_LAYOUT,
    TD_CONVENTION,
    ImuEdgeResult,
    ImuEstimate,
    ImuGate,
    ImuInput,
    ImuMetrics,
    ImuModelEstimate,
    ImuNoiseModel,
    ImuRowBin,
    ImuRowTest,
    ImuSeries,
)
from calibctl.artifacts.rig import RigCalibration
from calibctl.config import Settings
from calibctl.core.extrinsics import se3
from calibctl.core.imu import intrinsics
from calibctl.core.imu.calibrate import Calibration, calibrate_cameras
from calibctl.core.imu.plain import board_track
from calibctl.core.imu.rows import ReportSeries, RowTest, report_series, row_test
from calibctl.core.imu.samples import CameraFrames, ImuInputError, ImuNoise
from calibctl.core.imu.solve import ImuCameraSolution, SolveOptions
from calibctl.core.intrinsics.solve import is_fisheye
from calibctl.errors import AlreadyExistsError, InputError, NotFoundError, UsageError
from calibctl.files import existing_target, write_atomic
from calibctl.workflows.edges import versions
from calibctl.workflows.edges.kinds import IMU
from calibctl.workflows.exports import sealed_result
from calibctl.workflows.imu.bags import is_bag, read_bag
from calibctl.workflows.imu.recording import Board, Recording, read_noise, read_recording
from calibctl.workflows.store_admin import keys
from calibctl.workflows.store_admin.records import open_store

IMU_MODELS = intrinsics.IMU_MODELS  # what --imu-model accepts
FREE_TRY = "td_rotation_correlation_free"  # core.imu.calibrate: the correlation before td was held


@dataclass(frozen=True)
class ImuRequest:
    """What the command line asked for. ``hold_td_s``: the td to hold when the motion cannot separate td
    from the extrinsic rotation (a hardware-triggered rig knows 0); None: refuse instead."""

    recording: Path
    serial: str
    camera: str = "cam0"
    noise: Path | None = None
    imu_frame: str = "imu"
    rig: str | None = None
    hold_td_s: float | None = None
    line_delay: bool = False
    knot_spacing_s: float = 0.05
    folds: int = 3
    out: Path | None = None
    force: bool = False
    board: str | None = None  # registered NAME[@REV]: detects corners in images, checks corner files'
    image_topic: str | None = None  # a ROS bag's sensor_msgs/Image (or CompressedImage) topic
    imu_topic: str | None = None  # a ROS bag's sensor_msgs/Imu topic
    more: tuple[tuple[str, str], ...] = ()  # further (camera folder, serial) solved jointly with the first
    imu_model: str = "calibrated"  # core.imu.intrinsics.IMU_MODELS: Kalibr's IMU models
    bias_walk: bool = False  # the biases as random walks (core.imu.solve.SolveOptions.bias_walk)


@dataclass
class ImuOutcome:
    """The verdict and everything it rests on; ``stored`` / ``written`` filled by ``run_imu``."""

    request: ImuRequest
    camera: str  # SERIAL@VERSION whose intrinsics were held
    recording: Recording
    noise: ImuNoise
    noise_source: str
    calibration: Calibration
    board: str | None = None  # NAME@REV read from the store
    rows: RowTest | None = None  # the row test on the solved residuals
    series: ReportSeries | None = None  # what the report page plots over time
    stored: RigCalibration | None = None
    written: list[str] = field(default_factory=list)
    others: list[ImuOutcome] = field(default_factory=list)  # the further cameras of a joint solve
    held_by_rig: str | None = None  # the rig path that holds this camera's pose to the first camera's

    @property
    def cameras(self) -> list[ImuOutcome]:
        """This camera's outcome and the further cameras', in the order given."""
        return [self, *self.others]

    @property
    def solution(self) -> ImuCameraSolution | None:
        return self.calibration.solution

    @property
    def accepted(self) -> bool:
        return self.solution is not None and self.calibration.passed

    @property
    def status(self) -> str:
        return "accepted" if self.accepted else "rejected"


def camera_intrinsics(
    settings: Settings, serial: str
) -> tuple[str, tuple[np.ndarray, np.ndarray, tuple[int, int]]]:
    """SERIAL@VERSION of the camera's active calibration and its (K, distortion, image size)."""
    with open_store(settings) as store:
        try:
            art = store.get_artifact(serial, None)
        except NotFoundError:
            raise NotFoundError(
                f"camera {serial} has no active calibration",
                f"calibrate {serial} (or roll it back to an accepted version), then run `calibctl imu solve`",
            ) from None
    if is_fisheye(art.model.name):
        raise UsageError(
            f"camera {art.ref} is calibrated with the {art.model.name} model; the camera-IMU solve holds "
            "pinhole intrinsics with OpenCV's distortion",
            f"calibrate {serial} with a pinhole model (--model k1k2p1p2k3) for the IMU solve",
        )
    K = np.array(art.camera_matrix, np.float64)
    size = (int(art.image_size[0]), int(art.image_size[1]))
    return art.ref, (K, np.array(art.dist_coeffs, np.float64), size)


def registered_board(settings: Settings, ref: str) -> Board:
    """The registered board ``NAME[@REV]`` (NotFoundError, exit 2, for an unknown one)."""
    from calibctl.workflows.board.boards import board_ref, board_spec

    name, revision = board_ref(ref)
    with open_store(settings) as store:
        board = store.get_board(name, revision)
    return Board(board.ref, board_spec(board), board.measurement.status == "nominal")


def _camera_pairs(req: ImuRequest) -> list[tuple[str, str]]:
    """(camera folder, serial) of every camera solved, refusing a folder or serial named twice."""
    pairs = [(req.camera, req.serial), *req.more]
    for k, what in ((0, "camera folder"), (1, "serial")):
        names = [p[k] for p in pairs]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise UsageError(
                f"the {what} {', '.join(twice)} is named twice",
                "give each camera once: --camera FOLDER --serial SERIAL, in pairs",
            )
    if len(pairs) > 1 and is_bag(req.recording):
        raise UsageError(
            f"{req.recording} is a ROS bag: a bag's image topic is one camera",
            "solve several cameras from a recording folder (cam0/, cam1/, ...) instead",
        )
    return pairs


def _on_origin(rec: Recording, first: Recording) -> Recording:
    """``rec`` (another camera of the same recording) on ``first``'s time origin and IMU samples."""
    shift_s = (rec.t0_ns - first.t0_ns) * 1e-9
    f = rec.frames
    frames = CameraFrames(
        f.t_s + shift_s, f.object_points, f.image_points, f.camera_matrix, f.dist_coeffs, f.image_size
    )
    return replace(rec, imu=first.imu, frames=frames, t0_ns=first.t0_ns)


def rig_poses(settings: Settings, req: ImuRequest) -> dict[str, tuple[np.ndarray, str]]:
    """Cameras the rig's active tree relates to the first camera without passing the IMU frame: serial
    -> (T_cam0_cam (4, 4), the path in words). Empty without ``--rig``."""
    if req.rig is None:
        return {}
    with open_store(settings) as store:
        cal = store.get_rig_calibration(req.rig, None)
    edges = [e for e in cal.edges if req.imu_frame not in (e.parent, e.child)]
    poses: dict[str, tuple[np.ndarray, str]] = {req.serial: (np.eye(4), req.serial)}
    grown = True
    while grown:  # the tree is small: walk it from the first camera, either way along each edge
        grown = False
        for e in edges:
            T = np.array(e.T_parent_child, np.float64)
            for a, b, T_ab in ((e.parent, e.child, T), (e.child, e.parent, se3.invert(T))):
                if a in poses and b not in poses:
                    poses[b] = (poses[a][0] @ T_ab, f"{poses[a][1]} -> {b}")
                    grown = True
    where = f" of rig {cal.rig}@{cal.version}"
    return {s: (T, path + where) for s, (T, path) in poses.items() if s != req.serial}


def solve(settings: Settings, req: ImuRequest) -> ImuOutcome:
    """Read and solve (module docstring); nothing stored."""
    pairs = _camera_pairs(req)
    related = rig_poses(settings, req)
    held = [camera_intrinsics(settings, serial) for _, serial in pairs]
    board = None if req.board is None else registered_board(settings, req.board)
    noise, source = read_noise(req.noise)
    if is_bag(req.recording):
        if req.image_topic is None or req.imu_topic is None:
            raise UsageError(
                f"{req.recording} is a ROS bag: name its topics",
                "pass --image-topic (sensor_msgs/Image) and --imu-topic (sensor_msgs/Imu)",
            )
        recs = [read_bag(req.recording, req.image_topic, req.imu_topic, held[0][1], board)]
    else:
        recs = [
            read_recording(req.recording, cam, intr, board)
            for (cam, _), (_, intr) in zip(pairs, held, strict=True)
        ]
        recs = [recs[0], *(_on_origin(r, recs[0]) for r in recs[1:])]
    if board is not None and board.nominal:  # a camera made with it fails lint; here the metres depend on it
        recs[0].notes.append(
            f"board {board.ref}'s size is nominal (typed, never measured): the translation scales with it; "
            f"measure it (`calibctl board add {board.ref.split('@')[0]} ... --uncertainty-mm ...`)"
        )
    options = SolveOptions(
        knot_spacing_s=req.knot_spacing_s,
        estimate_line_delay=req.line_delay,
        folds=req.folds,
        imu_model=req.imu_model,
        bias_walk=req.bias_walk,
    )
    try:
        cals = calibrate_cameras(
            recs[0].imu,
            [r.frames for r in recs],
            noise,
            options,
            fallback_td_s=req.hold_td_s,
            rig=[None] + [related[s][0] if s in related else None for _, s in pairs[1:]],
            square_mm=None if board is None else 1e3 * board.spec.square_size_m,
        )
    except ImuInputError as exc:
        raise InputError(f"{req.recording}: {exc}", "fix the recording as the message says") from None
    ref = None if board is None else board.ref
    outcomes = [
        ImuOutcome(replace(req, camera=cam, serial=serial, more=()), camera, rec, noise, source, cal, ref)
        for (cam, serial), (camera, _), rec, cal in zip(pairs, held, recs, cals, strict=True)
    ]
    for o in outcomes:
        if o.solution is not None:
            track = board_track(o.recording.frames)
            o.rows = row_test(o.solution, o.recording.frames, track)
            o.series = report_series(o.solution, o.recording.imu, o.recording.frames, track)
    first = outcomes[0]
    for o in outcomes[1:]:
        o.held_by_rig = related[o.request.serial][1] if o.request.serial in related else None
        if o.held_by_rig is not None:  # its corners moved the first camera's edge: pin them there too
            first.recording.inputs.extend(i for i in o.recording.inputs if i[0] != "imu")
    first.request = req
    first.others = outcomes[1:]
    return first


def _vec3(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def estimate_of(outcome: ImuOutcome) -> ImuEstimate | None:
    s = outcome.solution
    if s is None:
        return None
    w, x, y, z = (float(v) for v in se3.quaternion_from_rotation(s.T_imu_cam[:3, :3]))
    return ImuEstimate(
        T_imu_cam=tuple(tuple(float(v) for v in row) for row in s.T_imu_cam),
        quaternion_wxyz=(w, x, y, z),
        td_s=float(s.td_s),
        td_held=bool(s.td_held),
        td_held_reason=outcome.calibration.held_reason,
        covariance=[[float(v) for v in row] for row in s.covariance_7],
        sigma_translation_mm=_vec3(s.sigma_translation_mm),
        sigma_rotation_deg=_vec3(s.sigma_rotation_deg),
        sigma_td_ms=float(s.sigma_td_ms),
        td_crlb_ms=_finite(s.td_crlb_ms),
        sigma_inflation={k: float(v) for k, v in s.sigma_inflation.items() if np.isfinite(v)},
        line_delay_s=None if s.line_delay_s is None else float(s.line_delay_s),
        sigma_line_delay_us=None if s.sigma_line_delay_us is None else float(s.sigma_line_delay_us),
        gyro_bias_rad_s=_vec3(s.gyro_bias_rad_s),
        accel_bias_m_s2=_vec3(s.accel_bias_m_s2),
        gravity_board_m_s2=_vec3(s.gravity_w_m_s2),
        imu_model=imu_model_of(s),
    )


def imu_model_of(s: ImuCameraSolution) -> ImuModelEstimate | None:
    """The solved IMU model at full precision (None for Kalibr's ``calibrated`` IMU)."""
    m = s.imu_intrinsics
    if m is None:
        return None

    def rows(M: np.ndarray) -> tuple[tuple[float, float, float], ...]:
        return tuple(_vec3(row) for row in M)

    return ImuModelEstimate.model_validate(
        {
            "model": m.model,
            "gyro_M": rows(m.M_gyro),
            "gyro_C_gyro_i": rows(m.C_gyro_i),
            "gyro_A": rows(m.A_gyro),
            "accel_M": rows(m.M_accel),
            "states": dict(zip(intrinsics.NAMES, (float(v) for v in m.x), strict=True)),
            "sigmas": dict(zip(intrinsics.NAMES, (float(v) for v in m.sigma), strict=True)),
            "prior_sigmas": dict(
                zip(intrinsics.NAMES, (float(v) for v in intrinsics.PRIOR_SIGMAS), strict=True)
            ),
            "min_information": float(m.min_information),
        }
    )


def metrics_of(s: ImuCameraSolution | None, folds: int) -> ImuMetrics | None:
    if s is None:
        return None
    held = s.held_out
    return ImuMetrics(
        frames=s.n_frames,
        corners=s.n_corners,
        corners_left_out=s.n_outliers,
        imu_samples=s.n_imu,
        corner_rms_px=float(s.corner_rms_px),
        gyro_rms_rad_s=float(s.gyro_rms_rad_s),
        accel_rms_m_s2=float(s.accel_rms_m_s2),
        folds=folds if held is not None else 0,
        held_out_corner_rms_px=[] if held is None else [float(v) for v in held.corner_rms_px],
        held_out_gyro_rms_rad_s=[] if held is None else [float(v) for v in held.gyro_rms_rad_s],
        held_out_accel_rms_m_s2=[] if held is None else [float(v) for v in held.accel_rms_m_s2],
        iterations=s.iterations,
        converged=bool(s.converged),
    )


def _opt(v: float, digits: int) -> float | None:
    return round(float(v), digits) if np.isfinite(v) else None


def row_test_of(outcome: ImuOutcome) -> ImuRowTest | None:
    t = outcome.rows
    if t is None:
        return None
    return ImuRowTest(
        slope_us_per_row=1e6 * t.slope_s_per_row,
        sigma_us_per_row=1e6 * t.sigma_s_per_row,
        offset_us=1e6 * t.offset_s,
        principal_row_px=float(outcome.recording.frames.camera_matrix[1, 2]),
        z=t.z,
        significant=t.significant,
        line_delay_solved=t.line_delay_solved,
        corners=t.corners,
        message=t.message,
        rows=[
            ImuRowBin(
                row_px=float(r), time_residual_us=_opt(1e6 * m, 3), sigma_us=_opt(1e6 * e, 3), corners=int(n)
            )
            for r, m, e, n in zip(t.row_px, t.time_residual_s, t.sigma_s, t.counts, strict=True)
        ],
    )


def series_of(outcome: ImuOutcome) -> ImuSeries | None:
    """The plotted series, rounded to what a 480-pixel plot can show (they are not estimates)."""
    s = outcome.series
    if s is None:
        return None

    def rows3(a: np.ndarray, digits: int) -> list[tuple[float | None, float | None, float | None]]:
        return [(_opt(x, digits), _opt(y, digits), _opt(z, digits)) for x, y, z in a]

    return ImuSeries(
        t_s=[round(float(v), 4) for v in s.t_s],
        gyro_rad_s=rows3(s.gyro_rad_s, 5),
        camera_rate_rad_s=rows3(s.camera_rate_rad_s, 5),
        corner_rms_px=[_opt(v, 4) for v in s.corner_rms_px],
        gyro_rms_rad_s=[_opt(v, 6) for v in s.gyro_rms_rad_s],
        accel_rms_m_s2=[_opt(v, 5) for v in s.accel_rms_m_s2],
    )


def evidence(outcome: ImuOutcome) -> ImuEdgeResult:
    """The typed result as the rig edge's evidence ``imu_frame -> serial``, at full precision."""
    req, s, n = outcome.request, outcome.solution, outcome.noise
    factors = (
        (1.0, 1.0) if s is None else (float(s.imu_variance_factors[0]), float(s.imu_variance_factors[1]))
    )
    return ImuEdgeResult(
        parent_frame=req.imu_frame,
        child_frame=req.serial,
        status="accepted" if outcome.accepted else "rejected",
        camera=outcome.camera,
        recording=str(req.recording),
        board=outcome.board,
        estimate=estimate_of(outcome),
        noise=ImuNoiseModel(
            gyro_noise_density=n.gyro_noise_density,
            accel_noise_density=n.accel_noise_density,
            gyro_random_walk=n.gyro_random_walk,
            accel_random_walk=n.accel_random_walk,
            gravity_m_s2=n.gravity_m_s2,
            rate_hz=float(outcome.recording.imu.rate_hz),
            variance_factors=factors,
            source=outcome.noise_source,
        ),
        metrics=metrics_of(s, req.folds),
        # the failed first try before td was held is told by td_held_reason, not judged again by lint
        gates=[ImuGate.from_result(g) for g in outcome.calibration.gates if g.gate != FREE_TRY],
        inputs=[
            ImuInput.model_validate({"role": role, "path": str(path.resolve()), "sha256": sha})
            for role, path, sha in outcome.recording.inputs
        ],
        created_at=utc_now(),
        row_test=row_test_of(outcome),
        series=series_of(outcome),
    )


def _r(v: float | None, digits: int) -> float | None:
    return None if v is None or not np.isfinite(v) else round(float(v), digits)


def result_json(outcome: ImuOutcome) -> dict[str, Any]:
    """The result as people and scripts read it (``--json``, ``-o``): rounded; the evidence is built from
    ``outcome`` itself at full precision."""
    s = outcome.solution
    doc: dict[str, Any] = {
        "recording": str(outcome.request.recording),
        "camera": outcome.camera,
        "board": outcome.board,
        "frames": int(outcome.recording.frames.t_s.size),
        "imu_samples": int(outcome.recording.imu.t_s.size),
        "imu_rate_hz": _r(outcome.recording.imu.rate_hz, 2),
        "noise": outcome.noise_source,
        "notes": list(outcome.recording.notes),
        "status": outcome.status,
        "held": outcome.calibration.held,
        "held_reason": outcome.calibration.held_reason,
        "gates": [
            {
                "gate": g.gate,
                "passed": g.passed,
                "value": _r(g.value, 4),
                "threshold": _r(g.threshold, 4),
                "message": g.message,
                "hint": g.hint,
            }
            for g in outcome.calibration.gates
        ],
        "estimate": None,
        "row_test": None,
    }
    if s is not None:
        T = s.T_imu_cam
        doc["estimate"] = {
            "name": "T_imu_cam",
            "convention": "p_imu = R p_cam + t (camera frame into the IMU frame), metres",
            "matrix": [[round(float(v), 9) for v in row] for row in T],
            "translation_m": [round(float(v), 6) for v in T[:3, 3]],
            "sigma_translation_mm": [round(float(v), 3) for v in s.sigma_translation_mm],
            "sigma_rotation_deg": [round(float(v), 4) for v in s.sigma_rotation_deg],
            "td_ms": round(1e3 * s.td_s, 4),
            "td_convention": TD_CONVENTION,
            "td_held": s.td_held,
            "sigma_td_ms": _r(s.sigma_td_ms, 4),
            "td_crlb_ms": _r(s.td_crlb_ms, 4),
            "sigma_inflation": {
                k: round(float(v), 3) for k, v in s.sigma_inflation.items() if np.isfinite(v)
            },
            "line_delay_us": None if s.line_delay_s is None else round(1e6 * s.line_delay_s, 3),
            "sigma_line_delay_us": _r(s.sigma_line_delay_us, 3),
            "gyro_bias_rad_s": [round(float(v), 6) for v in s.gyro_bias_rad_s],
            "accel_bias_m_s2": [round(float(v), 5) for v in s.accel_bias_m_s2],
            "gravity_board_m_s2": [round(float(v), 5) for v in s.gravity_w_m_s2],
            "covariance": [[float(v) for v in row] for row in s.covariance_7],
            "covariance_layout": COVARIANCE_LAYOUT,
            "T_cam_imu": [[round(float(v), 9) for v in row] for row in s.T_cam_imu],
            "timeshift_cam_imu_s": round(float(s.timeshift_cam_imu_s), 9),
            "imu_model": outcome.request.imu_model,
            "bias_walk": outcome.request.bias_walk,
        }
        model = imu_model_of(s)
        if model is not None:
            doc["estimate"]["imu_intrinsics"] = {
                "states": {k: round(v, 6) for k, v in model.states.items()},
                "sigmas": {k: round(v, 6) for k, v in model.sigmas.items()},
                "min_information": round(model.min_information, 2),
            }
        m = metrics_of(s, outcome.request.folds)
        assert m is not None
        doc["metrics"] = m.model_dump(mode="json")
        rows = row_test_of(outcome)
        if rows is not None:
            doc["row_test"] = {
                "slope_us_per_row": round(rows.slope_us_per_row, 3),
                "sigma_us_per_row": round(rows.sigma_us_per_row, 3),
                "offset_us": round(rows.offset_us, 3),
                "z": round(rows.z, 2),
                "significant": rows.significant,
                "corners": rows.corners,
                "message": rows.message,
            }
    if outcome.others:
        doc["serial"] = outcome.request.serial
        doc["camera_folder"] = outcome.request.camera
        doc["more_cameras"] = [
            {
                **result_json(o),
                "serial": o.request.serial,
                "camera_folder": o.request.camera,
                "held_by_rig": o.held_by_rig,
            }
            for o in outcome.others
        ]
    return doc


def run_imu(settings: Settings, req: ImuRequest) -> ImuOutcome:
    """The whole command (module docstring)."""
    if req.out is not None and not req.force and existing_target(req.out) is not None:
        raise AlreadyExistsError(  # checked before the solve: a stored version never goes without its file
            f"{req.out} already exists; nothing was solved or stored", "pass --force to overwrite it"
        )
    if req.rig is not None:
        related = rig_poses(settings, req)
        for _, serial in _camera_pairs(req):
            if serial not in related:
                versions.check_sensor_target(settings, req.rig, req.imu_frame, serial, IMU, "--imu-frame")
    outcome = solve(settings, req)
    if req.rig is not None:
        for o in outcome.cameras:  # one version per camera's own edge, in the order given
            if o.held_by_rig is None:
                o.stored = versions.store_evidence(settings, req.rig, evidence(o)).calibration
    if req.out is not None:  # hashed, and signed with a configured key: `lint FILE` checks both
        sealed = sealed_result.seal(result_json(outcome), sealed_result.IMU_RESULT, keys.signer_of(settings))
        text = json.dumps(sealed, indent=2, allow_nan=False) + "\n"
        write_atomic(req.out, text, force=req.force)
        outcome.written.append(f"wrote {req.out}")
    return outcome
