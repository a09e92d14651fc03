"""Seeded synthetic rig sessions for the rig tests: corner-level (fast) and rendered (slow)."""

from __future__ import annotations

import numpy as np

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture.detect import detect_board
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.synth.rig import RigTruth, render_rig_frame, rig_corners, synthesize_rig

BOARD = BoardSpec.chessboard(9, 6, 0.025)


def views_from(truth: RigTruth, corners: list[list[np.ndarray | None]], board: BoardSpec = BOARD) -> RigViews:
    ids = np.arange(board.n_corners)
    rows = tuple(
        tuple(BoardView(f"f{f}", ids, c) if c is not None else None for c in row)
        for f, row in enumerate(corners)
    )
    return RigViews(truth.names, board.object_points(), tuple(f"f{f}" for f in range(len(corners))), rows)


def true_members(truth: RigTruth) -> list[MemberIntrinsics]:
    return [
        MemberIntrinsics(n, c.K, c.dist, c.image_size)
        for n, c in zip(truth.names, truth.cameras, strict=True)
    ]


def corner_session(
    n_cameras: int,
    seed: int,
    n_frames: int = 20,
    noise_px: float = 0.2,
    baselines_m: tuple[float, ...] | None = None,
    min_cameras: int = 2,
) -> tuple[RigTruth, RigViews]:
    rng = np.random.default_rng(seed)
    truth = synthesize_rig(n_cameras, BOARD, n_frames, rng, baselines_m=baselines_m, min_cameras=min_cameras)
    return truth, views_from(truth, rig_corners(truth, BOARD, noise_px, rng))


def rendered_session(
    n_cameras: int,
    seed: int,
    n_frames: int,
    baselines_m: tuple[float, ...] | None = None,
    min_cameras: int = 2,
) -> tuple[RigTruth, RigViews]:
    """Render every frame, detect with calibctl's detector; a missed detection is a missing view."""
    rng = np.random.default_rng(seed)
    truth = synthesize_rig(n_cameras, BOARD, n_frames, rng, baselines_m=baselines_m, min_cameras=min_cameras)
    rows = []
    for f in range(n_frames):
        row: list[BoardView | None] = []
        for image in render_rig_frame(truth, BOARD, f, rng):
            det = detect_board(image, BOARD)[0] if image is not None else None
            row.append(BoardView(f"f{f}", det.corner_ids, det.corners_px) if det is not None else None)
        rows.append(tuple(row))
    return truth, RigViews(
        truth.names, BOARD.object_points(), tuple(f"f{f}" for f in range(n_frames)), tuple(rows)
    )
