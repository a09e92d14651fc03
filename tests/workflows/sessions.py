"""Capture sessions made from seeded synthetic corners, for workflow tests that start after capture."""

from __future__ import annotations

import datetime as dt

import numpy as np

from calibctl.artifacts.board import BoardRevision
from calibctl.artifacts.session import CaptureSession, GateResult, ViewCorners
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.detect import detect_board
from calibctl.core.synth.corners import synthesize_session
from calibctl.core.synth.pinhole import Photometry, PinholeCamera, render_view
from calibctl.core.synth.scenes import scenario_poses

K_TRUE = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])
T0 = dt.datetime(2026, 3, 11, 10, 0, tzinfo=dt.UTC)


def synthetic_capture(
    board: BoardRevision,
    serial: str = "CAM-0001",
    session_id: str = "0123456789ab",
    n_views: int = 18,
    seed: int = 7,
    tilt_deg: tuple[float, float] = (20.0, 40.0),
    status: str = "accepted",
    camera_matrix: np.ndarray = K_TRUE,
    noise_px: float = 0.2,
) -> CaptureSession:
    syn = synthesize_session(
        camera_matrix,
        D_TRUE,
        (640, 480),
        n_views,
        seed,
        noise_px=noise_px,
        tilt_deg=tilt_deg,
        cols=board.cols,
        rows=board.rows,
        square_size_m=board.measurement.square_size_m,
    )
    views = [
        ViewCorners(
            name=f"view{i:02d}.png",
            corner_ids=list(range(board.cols * board.rows)),
            corners_px=[(float(u), float(v)) for u, v in img],
        )
        for i, img in enumerate(syn.image_points_per_view)
    ]
    gate = GateResult(gate="observability", passed=status == "accepted", value=2e-4, threshold=1e-4)
    return CaptureSession(
        session_id=session_id,
        serial=serial,
        board=board,
        source="synthetic",
        source_kind="synthetic",
        station="st1",
        operator="op",
        started_at=T0,
        finished_at=T0,
        image_size=(640, 480),
        status=status,  # type: ignore[arg-type]
        gates=[gate],
        views=views,
        calibctl_version="0.1.0",
        opencv_version="5.0.0",
    )


def fisheye_capture(
    board: BoardRevision,
    fov_deg: float = 170.0,
    circular: bool = True,
    serial: str = "FE-0001",
    session_id: str = "fe0123456789",
    n_views: int = 18,
    seed: int = 11,
) -> CaptureSession:
    """A capture through a seeded equidistant fisheye (calibctl.core.synth.fisheye) at 1280x960."""
    from calibctl.core.synth.fisheye import FisheyeCamera, synthesize_fisheye_session

    camera = FisheyeCamera.from_fov((1280, 960), fov_deg, circular)
    syn = synthesize_fisheye_session(
        camera, n_views, seed, cols=board.cols, rows=board.rows, square_size_m=board.measurement.square_size_m
    )
    base = synthetic_capture(board, serial=serial, session_id=session_id, n_views=2)
    views = [
        ViewCorners(
            name=f"fisheye{i:02d}.png",
            corner_ids=list(range(board.cols * board.rows)),
            corners_px=[(float(u), float(v)) for u, v in img],
        )
        for i, img in enumerate(syn.image_points_per_view)
    ]
    return base.model_copy(update={"views": views, "image_size": (1280, 960)})


# Renders through the real detector with a camera that changes during the session
# (core.intrinsics.camera_change, benchmarks/bench_camera_change.py): the seed lens at 640x480, 9x6
# chessboard, scenario good, 20 views.
CHANGE_BOARD = BoardSpec.chessboard(9, 6, 0.025)
CHANGE_SIZE = (640, 480)
CHANGE_VIEWS = 20
CHANGE_AT = 10


def _stepped(cam: PinholeCamera, focal: float, centre: tuple[float, float]) -> PinholeCamera:
    K = cam.K.copy()
    K[0, 0] *= 1 + focal
    K[1, 1] *= 1 + focal
    K[0, 2] += centre[0]
    K[1, 2] += centre[1]
    return PinholeCamera(K, cam.dist, cam.image_size)


def rendered_views(
    seed: int, focal: float = 0.0, centre: tuple[float, float] = (0.0, 0.0), n_views: int = CHANGE_VIEWS
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(corner ids, detected corners px) per view in capture order; from view CHANGE_AT on the camera's
    focal length is (1 + focal) x and its principal point ``centre`` px away."""
    cam = PinholeCamera.seed_reference(CHANGE_SIZE)
    after = _stepped(cam, focal, centre)
    rng = np.random.default_rng(seed)
    out = []
    for i, T in enumerate(scenario_poses("good", cam, CHANGE_BOARD, n_views, rng)):
        image = render_view(cam if i < CHANGE_AT else after, CHANGE_BOARD, T, rng, Photometry.random(rng))
        det, _ = detect_board(image, CHANGE_BOARD)
        if det is not None:
            out.append((np.asarray(det.corner_ids), np.asarray(det.corners_px, np.float64)))
    return out


def rendered_session(
    seed: int, focal: float = 0.0, centre: tuple[float, float] = (0.0, 0.0), n_views: int = CHANGE_VIEWS
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """``rendered_views`` as (object points, corners) per view, as the core solve takes them."""
    obj_all = CHANGE_BOARD.object_points()
    views = rendered_views(seed, focal, centre, n_views)
    return [obj_all[ids] for ids, _ in views], [px for _, px in views]


def changed_capture(
    board: BoardRevision, seed: int, focal: float = 0.0, centre: tuple[float, float] = (0.0, 0.0)
) -> CaptureSession:
    """``synthetic_capture`` of ``rendered_views`` (board: a 9x6 revision; views view00.png ... in capture
    order)."""
    base = synthetic_capture(board, n_views=1)
    views = [
        ViewCorners(
            name=f"view{i:02d}.png",
            corner_ids=[int(c) for c in ids],
            corners_px=[(float(u), float(v)) for u, v in px],
        )
        for i, (ids, px) in enumerate(rendered_views(seed, focal, centre))
    ]
    return base.model_copy(update={"views": views, "image_size": CHANGE_SIZE})
