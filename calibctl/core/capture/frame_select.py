"""Automatic frame selection for video and live sources, and a detector for consecutive frames.

``StreamDetector`` bounds the cost of board-free frames: the full cascade of ``detect.detect_board``
(50-300 ms on a board-free 1280x720 frame, mostly SB) runs on a frame when the previous frame had a
board, on every ``STREAM_FULL_SEARCH_EVERY``-th frame, or when ``cv2.checkChessboard`` on a copy of at
most ``STREAM_CHECK_SIDE_PX`` says the frame may hold one (a few ms). The quick check alone misses real
boards (29 of the 60 baka-stereo photos), so it only ever postpones a search: a board it misses is
found within ``STREAM_FULL_SEARCH_EVERY`` frames, and from then on every frame gets the full search,
as the stillness rule below needs.

Feed every frame's detection (or None) to ``FrameSelector.offer`` in order. A frame is kept only when

1. a board was found and it is sharp (the detector's blur limit),
2. the board is still: its corners moved less than ``still_frac`` x the image diagonal (mean over
   shared corner ids) since the previous frame - a frame with no previous detection cannot be shown
   to be still, so the first frame of a pause is never kept,
3. it is not a near-duplicate of a kept view (``image_outcomes.NEAR_DUPLICATE_FRAC``), and
4. it adds something the session lacks: a 3x3 coverage cell no kept view reaches, a pose bin (tilt
   direction x tilt band) no kept view has, or simply a view while the session has fewer than
   ``min_views``.

Tilt bands are [0, 10), [10, 20), [20, 30), [30, 45] and > 45 degrees; the direction is the 8-sector
compass direction of ``gates`` (only meaningful from 1 degree). A frame's tilt is read like the gates
read it (calibctl.core.capture.tilt): through the lens the last ``progress()`` fitted to the kept views,
through a pinhole at the session's focal guess before that; a frame with fewer than 8 corners has no tilt.
``progress()`` gives what a live view shows: coverage, tilt directions collected, the observability gauge
against its threshold, the view count and the gate hints in words.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from calibctl.core.board.board_spec import CHESSBOARD, BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.capture.detect import BLUR_MAX_EDGE_PX, Detection, DetectorSettings, detect_board
from calibctl.core.capture.gates import (
    CELL_NAMES,
    COVERAGE_GRID,
    DIRECTION_NAMES,
    GateReport,
    GateThresholds,
    cells_covered,
    direction_bin,
    estimate_focal_px,
    evaluate_gates,
    view_homography,
)
from calibctl.core.capture.image_circle import ImageCircle
from calibctl.core.capture.image_outcomes import NEAR_DUPLICATE_FRAC, mean_corner_motion_px
from calibctl.core.capture.tilt import (
    MIN_TILT_CORNERS,
    SessionLens,
    best_pose,
    nominal_camera,
    normal_tilt_direction,
)

STILL_FRAC = 0.003  # 2.4 px per frame on 640x480
STREAM_FULL_SEARCH_EVERY = 5
STREAM_CHECK_SIDE_PX = 640
TILT_BANDS_DEG = (10.0, 20.0, 30.0, 45.0)

KEPT = "kept"
NO_BOARD = "no_board"
BLURRED = "blurred"
MOVING = "moving"
NEAR_DUPLICATE = "near_duplicate"
ADDS_NOTHING = "adds_nothing"


@dataclass(frozen=True)
class SelectorSettings:
    still_frac: float = STILL_FRAC
    near_duplicate_frac: float = NEAR_DUPLICATE_FRAC
    blur_max_edge_px: float = BLUR_MAX_EDGE_PX
    thresholds: GateThresholds = GateThresholds()
    image_circle: ImageCircle | None = None  # a given image circle: coverage counts the cells inside it


@dataclass(frozen=True)
class FrameDecision:
    """What happened to one frame. ``adds`` names what a kept frame contributes."""

    index: int
    name: str
    status: str
    reason: str
    adds: tuple[str, ...] = ()
    motion_px: float | None = None
    tilt_deg: float | None = None
    direction_name: str | None = None

    @property
    def kept(self) -> bool:
        return self.status == KEPT


@dataclass(frozen=True)
class SelectionProgress:
    """The live view's data."""

    n_views: int
    covered: tuple[tuple[bool, ...], ...]
    directions: tuple[str, ...]
    observability: float
    observability_min: float
    missing: tuple[str, ...]
    report: GateReport


def tilt_band(tilt_deg: float) -> int:
    """0..4 for [0, 10), [10, 20), [20, 30), [30, 45], > 45 degrees."""
    return sum(tilt_deg >= edge for edge in TILT_BANDS_DEG[:-1]) + int(tilt_deg > TILT_BANDS_DEG[-1])


class FrameSelector:
    """Stateful, pure-logic frame selector (no I/O, no clocks)."""

    def __init__(
        self,
        spec: BoardSpec,
        image_size: tuple[int, int],
        settings: SelectorSettings | None = None,
        focal_px: float | None = None,
    ) -> None:
        self.spec = spec
        self.image_size = image_size
        self.settings = settings or SelectorSettings()
        self.model = spec.object_points()
        self.diag_px = math.hypot(*image_size)
        self.focal_px = focal_px
        self.kept: list[BoardView] = []
        self.decisions: list[FrameDecision] = []
        self._previous: Detection | None = None
        self._cells: set[tuple[int, int]] = set()
        self._pose_bins: set[tuple[int, int]] = set()
        self._homographies: list[np.ndarray] = []
        self._lens: SessionLens | None = None  # the gates' lens fit of the kept views, from progress()

    def _focal(self) -> float:
        if self.focal_px is not None:
            return self.focal_px
        estimate = (
            estimate_focal_px(self._homographies, self.image_size) if len(self._homographies) >= 2 else None
        )
        return estimate if estimate is not None else self.diag_px

    def offer(self, index: int, detection: Detection | None, name: str | None = None) -> FrameDecision:
        """Decide on frame ``index`` (frames must come in order)."""
        name = name or f"frame-{index:06d}"
        previous, self._previous = self._previous, detection
        decision = self._decide(index, name, detection, previous)
        self.decisions.append(decision)
        return decision

    def _decide(
        self, index: int, name: str, det: Detection | None, previous: Detection | None
    ) -> FrameDecision:
        s = self.settings
        if det is None:
            return FrameDecision(index, name, NO_BOARD, "no board in the frame")
        if det.edge_width_px is not None and det.edge_width_px > s.blur_max_edge_px:
            return FrameDecision(index, name, BLURRED, f"board edges {det.edge_width_px:.1f} px wide")
        motion = (
            None
            if previous is None
            else mean_corner_motion_px(
                det.corner_ids, det.corners_px, previous.corner_ids, previous.corners_px
            )
        )
        still_px = s.still_frac * self.diag_px
        if motion is None or motion >= still_px:
            why = (
                "board not seen in the previous frame"
                if motion is None
                else (
                    f"board moving: {motion:.1f} px since the previous frame (still is under "
                    f"{still_px:.1f} px)"
                )
            )
            return FrameDecision(index, name, MOVING, why, motion_px=motion)
        dup_px = s.near_duplicate_frac * self.diag_px
        for view in self.kept:
            moved = mean_corner_motion_px(det.corner_ids, det.corners_px, view.corner_ids, view.corners_px)
            if moved is not None and moved < dup_px:
                return FrameDecision(
                    index,
                    name,
                    NEAR_DUPLICATE,
                    f"same view as {view.name} ({moved:.1f} px)",
                    motion_px=motion,
                )
        H = view_homography(self.model[det.corner_ids, :2], det.corners_px)
        tilt = direction = None
        pose_bin = None
        if H is not None and len(det.corner_ids) >= MIN_TILT_CORNERS:
            lens = self._lens or SessionLens(
                nominal_camera(self.image_size, self._focal()), np.zeros(5), "pinhole"
            )
            rvec, _ = best_pose(self.model[det.corner_ids], det.corners_px, lens)
            tilt, direction_deg = normal_tilt_direction(rvec)
            bin_ = direction_bin(direction_deg) if tilt >= 1.0 else -1
            direction = DIRECTION_NAMES[bin_] if bin_ >= 0 else None
            pose_bin = (bin_, tilt_band(tilt))
        cells = cells_covered([det.corners_px], self.image_size)
        adds = [f"covers the {CELL_NAMES[r][c]}" for r, c in sorted(cells - self._cells)]
        if pose_bin is not None and pose_bin not in self._pose_bins:
            adds.append(f"tilt {tilt:.0f} deg" + (f" toward the {direction}" if direction else ""))
        if not adds and len(self.kept) < s.thresholds.min_views:
            adds.append(f"view {len(self.kept) + 1} of the {s.thresholds.min_views} needed")
        if not adds:
            return FrameDecision(
                index,
                name,
                ADDS_NOTHING,
                "adds no coverage or tilt the session lacks",
                motion_px=motion,
                tilt_deg=tilt,
                direction_name=direction,
            )
        self.kept.append(BoardView(name, det.corner_ids, det.corners_px))
        self._cells |= cells
        if pose_bin is not None:
            self._pose_bins.add(pose_bin)
        if H is not None:
            self._homographies.append(H)
        return FrameDecision(index, name, KEPT, "; ".join(adds), tuple(adds), motion, tilt, direction)

    def progress(self) -> SelectionProgress:
        """Gates on the kept views, for the live view."""
        report = evaluate_gates(
            self.kept,
            self.model,
            self.image_size,
            self.settings.thresholds,
            self.focal_px,
            image_circle=self.settings.image_circle,
        )
        self._lens = report.lens
        covered = tuple(
            tuple((r, c) in self._cells for c in range(COVERAGE_GRID)) for r in range(COVERAGE_GRID)
        )
        obs = report.gate("observability")
        return SelectionProgress(
            len(self.kept),
            covered,
            report.tilt_directions,
            obs.value,
            obs.threshold,
            tuple(report.hints),
            report,
        )


@dataclass(frozen=True)
class Probe:
    """What ``probe_frame`` found in one frame: the full search's answer (``searched``), or only that the
    quick check saw nothing chessboard-like (``searched`` False, ``detection`` None)."""

    searched: bool
    detection: Detection | None
    why: str


def probe_frame(gray: np.ndarray, spec: BoardSpec, settings: DetectorSettings | None, search: bool) -> Probe:
    """One frame's detection as far as it can be decided without the previous frame: the full search when
    ``search`` (the frame is due whatever came before), a ChArUco board (no quick check), or the quick check
    passes; else the quick check's "nothing here". Pure, so it runs ahead on another worker
    (``StreamDetector.settle`` finishes it in frame order)."""
    if not search and spec.kind == CHESSBOARD and _quick_reject(gray, spec):
        return Probe(
            False, None, f"no {spec.cols}x{spec.rows} chessboard: nothing chessboard-like at a quick look"
        )
    detection, why = detect_board(gray, spec, settings)
    return Probe(True, detection, why)


def _quick_reject(gray: np.ndarray, spec: BoardSpec) -> bool:
    height, width = gray.shape[:2]
    k = max(1, -(-max(width, height) // STREAM_CHECK_SIDE_PX))
    small = gray if k == 1 else cv2.resize(gray, (width // k, height // k), interpolation=cv2.INTER_AREA)
    return not cv2.checkChessboard(small, (spec.cols, spec.rows))


class StreamDetector:
    """``detect_board`` for consecutive frames of one stream, with the quick check in front (see the
    module docstring). Pure logic: no I/O, no clocks.

    In one thread: ``detect(gray)`` per frame, in order. Ahead on workers, with the same answers: per frame in
    order ``forced = next_forced()``, then ``probe_frame(gray, spec, settings, forced)`` anywhere, then
    ``settle(gray, forced, probe)`` in order. A frame is due for the full search when it is forced (every
    ``full_every``-th) or the previous frame had a board; a probe run ahead knows only the first, so a due
    frame whose quick check said "nothing" is searched in ``settle`` - the search the one-thread detector
    would have run, hence the same answer for every frame whatever ran ahead.
    """

    def __init__(
        self,
        spec: BoardSpec,
        settings: DetectorSettings | None = None,
        full_every: int = STREAM_FULL_SEARCH_EVERY,
    ) -> None:
        self.spec = spec
        self.settings = settings
        self.full_every = full_every
        self._frames = 0
        self._previous_found = False
        self.settled_searches = (
            0  # due frames searched in settle: the work a probe run ahead could not know of
        )

    def next_forced(self) -> bool:
        """Count the next frame; whether it gets the full search whatever the previous frame showed."""
        self._frames += 1
        return self.full_every <= 1 or self._frames % self.full_every == 1

    def settle(self, gray: np.ndarray, forced: bool, probe: Probe) -> tuple[Detection | None, str]:
        """The frame's (Detection, "") or (None, why), in frame order, from its probe."""
        if probe.searched:
            detection, why = probe.detection, probe.why
        elif forced or self._previous_found:
            detection, why = detect_board(gray, self.spec, self.settings)
            self.settled_searches += 1
        else:
            self._previous_found = False
            return None, (
                f"{probe.why} (a full search runs on every {self.full_every}th frame and after each board)"
            )
        self._previous_found = detection is not None
        return detection, why

    def detect(self, gray: np.ndarray) -> tuple[Detection | None, str]:
        """(Detection, "") or (None, why) for the next frame, (H, W) uint8."""
        forced = self.next_forced()
        probe = probe_frame(gray, self.spec, self.settings, search=forced or self._previous_found)
        return self.settle(gray, forced, probe)
