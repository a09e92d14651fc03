"""Does the registered board match the board in the pictures? Two checks run by capture.

1. Nothing found: when no readable image (or frame) shows the registered pattern, a few images are
   probed with near patterns - the transposed one and one more or one fewer corner per side (OpenCV's
   ``patternSize`` counts *inner* corners, squares - 1 per side, an easy off-by-one) - and with the
   board findChessboardCornersSB sees when it may grow from a seed grid (``seen_sizes``, any size:
   a 16x12 registration on a 9x6 board is near nothing), confirmed by the classic detector. The error
   names what is visible: the pattern found in the most probed images, the largest on a tie (a part of
   the real board is found wherever the real board is).
2. A larger board: OpenCV's chessboard finder happily locks onto an inner part of a larger board. On
   ../shared/datasets/opencv-left-right (a 9x6 board) an 8x6 pattern is "found" in 13 of 13 images and
   a 7x6 one in 12 of 13; on udacity-camcal 8x6 is found in 4 of 20. Such views look accepted, but the
   board registry is wrong and the corner ids can slide by a column from view to view. So after
   detection a few accepted images are probed with one more column and one more row, classic detector
   only (findChessboardCornersSB reaches into a board's outer edge: it "finds" 9x7 on 3 of the 9x6
   left images, the classic detector on none), and the capture is refused when a larger pattern is
   found in at least ``LARGER_MIN_HITS`` of the probed images (the classic detector once found 10x6 on
   left13.jpg, a single image proves nothing). Probing stops once the verdict is settled, so a correctly
   registered board costs 4 failed classic searches (~0.3 s at 640x480 on this machine, 250-280 ms of
   the station path for 20 images at 1280x960). The whole board SB sees (``seen_sizes``) is probed
   first when it holds the registered pattern: on baka-stereo's 7x10 board registered as 9x6 the classic
   detector finds neither 10x6 nor 9x7 in most images, but 10x7 in all. SB alone is not trusted: grown
   from a seed on the 9x6 opencv-left-right board it reads 9x7 or 10x6 in 3 of 26 images.
   With fewer than two views showing the registered pattern the images without it are probed: a 7x10
   board registered as 9x6 shows a 9x6 part of itself in one stray image (OpenCV 5.0, baka-stereo left).
   So a cheap geometric pre-check runs first (``core.capture.board_extent.might_extend``, ~3 ms a view): a
   chessboard's inner corners are surrounded by exactly one ring of squares, so just past the ring
   there is margin or background, while on a larger board there is another row of alternating squares.
   The probe is skipped when the pre-check says "no" for every probed image (with its detected
   corners), and runs unchanged when any of them says "maybe" (no corners, a side whose row past the
   ring is mostly out of the image, or squares there). Measured (tests/core/capture/test_board_extent.py):
   registered one column or row short, it says "maybe" in every image the short pattern is found in
   (8x6: left 13/13, right 13/13, udacity 4/4; 9x5: udacity 3/3; 7x6: left 12/12, right 11/11; 9x5 is
   found in no left image), the missing side scoring 0.63-1.03 against a threshold of 0.2; every 9x6
   view of both datasets and 48 rendered ones with one outer corner line dropped also says "maybe". Correctly
   registered, it says "no" in left 10/13, right 9/13, udacity 15/18 (the rest: a side's row past the
   ring leaves the image, or right03's background scores 0.23) and 96/96 rendered views (`calibctl
   synth` scenarios good, flat, centre, one-direction at 640x480 and 1280x960; max score 0.01).
   A grossly smaller registration (5x4 on the 9x6 board) misses the +1 probes, but SB sees the 9x6
   board, so it is refused naming 9x6 (opencv-left-right left: found in left07 and left08).
ChArUco boards are not probed: their corner ids come from the markers, a partial view is normal.

Bounded: every probe searches a copy of at most ``PROBE_MAX_PIXELS`` (``probe_copies``), SB runs once per
probed picture (``visible_sizes``), and the nothing-found probe skips the pictures SB sees no chessboard in
once the first one showed no near pattern. Counted on 12 rendered views at 1280x960
(tests/workflows/station/test_station_probe_cost.py), against the 3.7 Mpx a clean unit's detection searches:
one picture with the board and 11 without, 11 probe calls searching 9.8 Mpx before, 2.5 Mpx now; no board
at all, 63 calls (about 50 Mpx at full size) before, 27 calls and 5.5 Mpx now. (One 20-view station unit
spent 4.66 s in these probes at full size.)
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np

from calibctl.core.board.board_spec import APRILGRID, CHESSBOARD, BoardSpec
from calibctl.core.capture.board_extent import might_extend, visible_chessboard
from calibctl.core.capture.detect import DetectorSettings, detect_board, downscaled_to_pixels
from calibctl.errors import InputError

PROBE_IMAGES = 3
LARGER_MIN_HITS = 2
PROBE_WORKERS = 2
# Each probe detection (classic or SB) searches a copy of at most this many pixels (an integer-factor block
# average, detect.downscaled_to_pixels): the real sets measured above (640x480, 1280x720) keep their full
# size, a 1280x960 picture is probed at 640x480 and a 4000x3000 one at 1000x750, so a probe costs what
# detecting a picture of about a megapixel costs, whatever the camera. Only found / not found is read.
PROBE_MAX_PIXELS = 1_000_000

Sample = tuple[str, np.ndarray]  # (image name, (H, W) uint8)
T = TypeVar("T")


def near_patterns(cols: int, rows: int) -> list[tuple[int, int]]:
    """The transposed pattern, one corner more / fewer on one side, then on both sides (each side >= 2)."""
    candidates = [
        (rows, cols),
        (cols + 1, rows),
        (cols - 1, rows),
        (cols, rows + 1),
        (cols, rows - 1),
        (cols + 1, rows + 1),
        (cols - 1, rows - 1),
        (cols + 1, rows - 1),
        (cols - 1, rows + 1),
    ]
    seen: list[tuple[int, int]] = []
    for c, r in candidates:
        if c >= 2 and r >= 2 and (c, r) != (cols, rows) and (c, r) not in seen:
            seen.append((c, r))
    return seen


def _found(sample: Sample, pattern: tuple[int, int], spec: BoardSpec, settings: DetectorSettings) -> bool:
    probe = BoardSpec.chessboard(pattern[0], pattern[1], spec.square_size_m)
    return detect_board(sample[1], probe, settings)[0] is not None


def probe(
    samples: Sequence[Sample],
    spec: BoardSpec,
    patterns: Sequence[tuple[int, int]],
    classic_only: bool = False,
) -> dict[tuple[int, int], list[str]]:
    """For each pattern, the names of the samples it is found in (samples x patterns detections)."""
    settings = DetectorSettings(sb_fallback=not classic_only)
    jobs = [(pattern, sample) for pattern in patterns for sample in samples]
    with ThreadPoolExecutor(max_workers=PROBE_WORKERS) as pool:
        hits = list(pool.map(lambda job: _found(job[1], job[0], spec, settings), jobs))
    found: dict[tuple[int, int], list[str]] = {pattern: [] for pattern in patterns}
    for (pattern, sample), hit in zip(jobs, hits, strict=True):
        if hit:
            found[pattern].append(sample[0])
    return found


def probe_copies(samples: Sequence[Sample]) -> list[Sample]:
    """The samples as the probes search them: each reduced to at most ``PROBE_MAX_PIXELS``."""
    return [(name, downscaled_to_pixels(gray, PROBE_MAX_PIXELS)[0]) for name, gray in samples]


def spread(items: Sequence[T], count: int) -> list[T]:
    """At most ``count`` items evenly spread over ``items`` (first and last included)."""
    if len(items) <= count:
        return list(items)
    picks = np.linspace(0, len(items) - 1, count).round().astype(int)
    return [items[i] for i in dict.fromkeys(picks.tolist())]


def _probe_near(
    samples: Sequence[Sample],
    spec: BoardSpec,
    patterns: Sequence[tuple[int, int]],
    sb_sees: Sequence[tuple[int, int] | None],
) -> dict[tuple[int, int], list[str]]:
    """``probe`` (classic detector), first the first sample with every pattern, then the other samples
    with the patterns it showed (9 + 2k detections instead of 27). When the first showed none, the other
    samples get every pattern, but only those in which SB sees a chessboard at all (``sb_sees``, one per
    sample: ``visible_chessboard``), so a unit of blank or boardless pictures costs 9 detections, not 27."""
    if not samples:
        return {}
    found = probe(samples[:1], spec, patterns, classic_only=True)
    again = [p for p, names in found.items() if names]
    rest = [s for s, seen in zip(samples[1:], sb_sees[1:], strict=True) if again or seen is not None]
    for pattern, names in probe(rest, spec, again or list(patterns), classic_only=True).items():
        found[pattern] += names
    return found


def _oriented(size: tuple[int, int], spec: BoardSpec) -> tuple[int, int]:
    """``size`` turned to read like the registered pattern (its longer side first when the pattern's is)."""
    a, b = sorted(size, reverse=spec.cols >= spec.rows)
    return a, b


def _holds_more(size: tuple[int, int], spec: BoardSpec) -> bool:
    """True when a board of ``size`` inner corners holds the registered pattern and more of it."""
    big, small = sorted(size, reverse=True)
    reg_big, reg_small = sorted((spec.cols, spec.rows), reverse=True)
    return big >= reg_big and small >= reg_small and big * small > reg_big * reg_small


def visible_sizes(samples: Sequence[Sample]) -> list[tuple[int, int] | None]:
    """Per sample, the chessboard findChessboardCornersSB sees growing from a seed grid
    (``board_extent.visible_chessboard``: whatever its size; None: none), SB's one call per sample."""
    with ThreadPoolExecutor(max_workers=PROBE_WORKERS) as pool:
        return list(pool.map(lambda sample: visible_chessboard(sample[1]), samples))


def seen_sizes(
    samples: Sequence[Sample], spec: BoardSpec, sizes: Sequence[tuple[int, int] | None] | None = None
) -> list[tuple[int, int]]:
    """The chessboards findChessboardCornersSB sees in the samples (``visible_sizes``, or ``sizes`` when
    they were looked for already), oriented like the registered pattern, the most often seen first, then the
    largest. A size still has to be confirmed by the classic detector."""
    seen = Counter(
        _oriented(size, spec)
        for size in (visible_sizes(samples) if sizes is None else sizes)
        if size is not None
    )
    return sorted(seen, key=lambda size: (seen[size], size[0] * size[1]), reverse=True)


def _a(cols: int, rows: int) -> str:
    """'a 9x6' / 'an 8x6' / 'an 11x7'."""
    text = f"{cols}x{rows}"
    return ("an " if text.startswith(("8", "11", "18")) else "a ") + text


def _names(names: Sequence[str]) -> str:
    return ", ".join(names[:-1]) + " and " + names[-1] if len(names) > 1 else names[0]


def nothing_found_error(
    spec: BoardSpec,
    board_ref: str,
    board_name: str,
    where: str,
    n_readable: int,
    samples: Sequence[Sample],
    given: str | None = None,
) -> InputError:
    """The error for "the registered pattern is in none of the readable pictures" (exit 2). ``given``: how
    the pattern was named when it is not a registered board (e.g. "--cols/--rows"), for the hint."""
    kind = f"{spec.cols}x{spec.rows} " + ("chessboard" if spec.kind == CHESSBOARD else "ChArUco board")
    if spec.kind == APRILGRID:
        kind = f"{spec.cols // 2}x{spec.rows // 2}-tag AprilGrid"
    named = f"board {board_ref}" if given is None else f"given as {board_ref}"
    message = f"no {kind} ({named}) was found in any of the {n_readable} readable {where}; nothing was stored"
    registry = f"`calibctl board show {board_name}`" if given is None else given
    if spec.kind != CHESSBOARD:
        printed = (
            "tags, tag spacing and family"
            if spec.kind == APRILGRID
            else "squares, marker size and dictionary"
        )
        return InputError(
            message,
            f"check the board's {printed} with {registry}, and that the board is in the frame, lit and "
            "in focus",
        )
    patterns = near_patterns(spec.cols, spec.rows)
    samples = probe_copies(spread(samples, PROBE_IMAGES))
    sb_sees = visible_sizes(samples)
    found = _probe_near(samples, spec, patterns, sb_sees)
    # a board two or more corners off is not among the near patterns: name what SB sees, once the classic
    # detector confirms it
    seen = [
        size
        for size in seen_sizes(samples, spec, sb_sees)
        if size not in found and size != (spec.cols, spec.rows)
    ]
    found.update(probe(samples, spec, seen, classic_only=True))
    # a sub-board of the real one is found wherever the real one is: prefer the most hits, then the largest
    visible = sorted(
        ((p, names) for p, names in found.items() if names),
        key=lambda item: (len(item[1]), item[0][0] * item[0][1]),
        reverse=True,
    )
    tried = ", ".join(f"{c}x{r}" for c, r in patterns)
    if visible:
        (c, r), names = visible[0]
        others = "".join(f"; {_a(pc, pr)} one in {_names(n)}" for (pc, pr), n in visible[1:3])
        message += f"; {_a(c, r)} chessboard is visible in {_names(names)}{others}"
        hint = _recount_hint(registry, c, r, given)
    else:
        probed = f"{len(samples)} of them" if samples else "none of them"
        message += f"; the near patterns {tried} are not visible either (probed {probed})"
        hint = (
            f"check the registered pattern with {registry} (inner corners, cols x rows, squares - 1 per "
            "side), "
            "and that the whole board is in the frame, lit and in focus"
        )
    return InputError(message, hint)


def _recount_hint(registry: str, c: int, r: int, given: str | None) -> str:
    """Count the corners again: check the registered board (or the options it was ``given`` by)."""
    return f"the pattern counts inner corners, cols x rows (squares - 1 per side): check {registry} and " + (
        f"capture with a board registered as {c}x{r}"
        if given is None
        else f"give the board seen, {c}x{r} inner corners (in the order your set lays it out)"
    )


def larger_board_error(
    spec: BoardSpec,
    board_ref: str,
    board_name: str,
    samples: Sequence[Sample],
    corners_px: Mapping[str, np.ndarray] | None = None,
    given: str | None = None,
) -> InputError | None:
    """An error when the pictures show a larger chessboard than the registered one, else None. ``given``:
    as for ``nothing_found_error``.

    ``corners_px``: the registered pattern's detected corners per sample name ((cols * rows, 2) float64,
    row-major). When every probed sample has them and ``board_extent.might_extend`` finds no sign of
    squares past the detected grid in any of them, the detector probe is skipped. A sample without
    corners counts as "maybe".
    """
    samples = spread(samples, PROBE_IMAGES)
    if spec.kind != CHESSBOARD or len(samples) < LARGER_MIN_HITS:
        return None
    known = corners_px or {}
    if all(
        name in known and not might_extend(gray, known[name], spec.cols, spec.rows) for name, gray in samples
    ):
        return None
    samples = probe_copies(samples)
    need = max(LARGER_MIN_HITS, len(samples) // 2 + 1)
    settings = DetectorSettings(sb_fallback=False)

    def hits_of(pattern: tuple[int, int]) -> list[str]:
        """Samples showing ``pattern``, stopping as soon as ``need`` is reached or out of reach: a correctly
        registered board costs 2 detections per pattern, not 3."""
        names: list[str] = []
        for i, sample in enumerate(samples):
            if len(names) + len(samples) - i < need or len(names) >= need:
                break
            if _found(sample, pattern, spec, settings):
                names.append(sample[0])
        return names

    # the whole board SB sees, when it holds the registered pattern (a 7x10 board registered as 9x6 shows
    # neither 10x6 nor 9x7 to the classic detector in most images), then one more column and one more row
    larger = [size for size in seen_sizes(samples, spec) if _holds_more(size, spec)]
    larger += [p for p in [(spec.cols + 1, spec.rows), (spec.cols, spec.rows + 1)] if p not in larger]
    with ThreadPoolExecutor(max_workers=PROBE_WORKERS) as pool:
        hits = [
            (p, names)
            for p, names in zip(larger, pool.map(hits_of, larger), strict=True)
            if len(names) >= need
        ]
    if not hits:
        return None
    (c, r), names = max(hits, key=lambda item: (len(item[1]), item[0][0] * item[0][1]))
    return InputError(
        f"the pictures show a larger board than {board_ref} ({spec.cols}x{spec.rows} inner corners): "
        f"{_a(c, r)} "
        f"chessboard is found in {_names(names)}. The detector locks onto {_a(spec.cols, spec.rows)} part "
        "of it, "
        "so corner ids could slide from view to view; nothing was stored",
        _recount_hint(f"`calibctl board show {board_name}`" if given is None else given, c, r, given),
    )
