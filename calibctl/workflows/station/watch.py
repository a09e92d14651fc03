"""The station's watch mode: a unit's pictures detected as they land, the unit captured once it is complete.

After the serial, the station polls the unit's folder (``core.capture.arrivals``: which files are
complete, by rename or by a size that settled) and starts each complete picture's detection at once on
the warm pool. The unit is complete when ``views`` pictures are complete, or when the camera app has
written ``done_file`` into the folder (after its last picture); then the station waits for the last
detections and runs the usual capture of the folder with them (``capture(..., detected=...)``), so only
the last picture's detection, the gates, the solve and the store are left when the last picture lands.

A file still being written (or settling) holds the unit open, so the capture never reads half a picture;
a unit whose pictures stop coming ends after ``unit_timeout_s`` without a new one (an error line naming
how many arrived; nothing stored); Ctrl-C while waiting cancels it (``station``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import wait
from dataclasses import dataclass
from pathlib import Path

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.arrivals import Arrivals, EarlyDetections
from calibctl.core.capture.image_circle import sized_half
from calibctl.core.capture.image_outcomes import IMAGE_SUFFIXES
from calibctl.errors import InputError, UsageError
from calibctl.workflows.camera import capture_sources as sources

DEFAULT_SETTLE_S = 0.25  # an app writing in place: far above the gap between one write() and the next
DEFAULT_UNIT_TIMEOUT_S = 120.0
POLL_S = 0.02  # one folder listing and a stat per picture: ~0.1 ms of CPU for 20 pictures


@dataclass(frozen=True)
class WatchRule:
    """When a unit's pictures are complete (``views`` and/or ``done_file``; at least one) and how long to
    wait."""

    views: int | None = None  # complete when this many pictures are complete
    done_file: str | None = None  # complete when the camera app has written this file into the unit's folder
    settle_s: float = DEFAULT_SETTLE_S  # 0: the app renames each picture into place (a listed file is whole)
    unit_timeout_s: float = DEFAULT_UNIT_TIMEOUT_S  # longest wait for the next picture
    poll_s: float = POLL_S


@dataclass(frozen=True)
class Watched:
    detected: EarlyDetections
    pictures: int
    last_in_s: float | None  # epoch seconds the last picture landed (its ctime: last write or rename)


def check_rule(rule: WatchRule) -> None:
    """A rule that cannot work is a usage error (exit 2) before the first unit."""
    if rule.views is None and rule.done_file is None:
        raise UsageError(
            "--watch needs --views N or --done-file NAME to know when a unit's pictures are all there",
            "give the number of pictures the camera app takes per unit, or the file it writes last",
        )
    if rule.views is not None and rule.views < 1:
        raise UsageError(f"--views must be 1 or more, got {rule.views}")
    if rule.done_file is not None and (
        Path(rule.done_file).name != rule.done_file
        or rule.done_file in (".", "..")
        or Path(rule.done_file).suffix.lower() in IMAGE_SUFFIXES
    ):
        raise UsageError(
            f"--done-file '{rule.done_file}' must be a file name in the unit's folder that is not an image",
            "e.g. --done-file DONE",
        )
    if not rule.settle_s >= 0:
        raise UsageError(f"--settle-s must be 0 or more seconds, got {rule.settle_s:g}")
    if not rule.unit_timeout_s > 0:
        raise UsageError(
            f"--unit-timeout-s must be a positive number of seconds, got {rule.unit_timeout_s:g}"
        )


def _complete(folder: Path, rule: WatchRule, arrivals: Arrivals) -> bool:
    if arrivals.pending:  # a picture still being written holds the unit open
        return False
    if rule.views is not None and arrivals.complete >= rule.views:
        return True
    return rule.done_file is not None and (folder / rule.done_file).is_file()


def _timed_out(folder: Path, rule: WatchRule, arrivals: Arrivals) -> InputError:
    wanted = "" if rule.views is None else f" of {rule.views}"
    writing = f", {arrivals.pending} more still being written" if arrivals.pending else ""
    marker = "" if rule.done_file is None else f"; no {rule.done_file} written"
    return InputError(
        f"no new picture in {folder} for {rule.unit_timeout_s:g} s (--unit-timeout-s): "
        f"{arrivals.complete}{wanted} arrived{writing}{marker}; nothing was stored",
        "check the camera app, then scan the serial again (the pictures already there are used)",
    )


def watch_unit(
    folder: Path,
    rule: WatchRule,
    spec: BoardSpec,
    workers: int,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> Watched:
    """Wait for the unit's pictures, detecting each as it lands; return when they are complete and detected.

    Raises InputError on the timeout; KeyboardInterrupt propagates (the detections not started are dropped).
    """
    arrivals = Arrivals(folder, rule.settle_s)
    detected = EarlyDetections(spec, workers, summarize=sized_half)  # as a folder capture detects
    last_arrival = clock()
    try:
        with sources.quiet_opencv():  # a truncated file is an outcome, not a decoder warning
            while True:
                now = clock()
                for path, sig in arrivals.poll(now):
                    detected.start(path, sig)
                    last_arrival = now
                if _complete(folder, rule, arrivals):
                    break
                if now - last_arrival >= rule.unit_timeout_s:
                    raise _timed_out(folder, rule, arrivals)
                sleep(rule.poll_s)
        wait(detected.futures())  # the last pictures' detections
    except BaseException:
        detected.cancel()
        raise
    last_ns = arrivals.last_in_ns()
    return Watched(detected, arrivals.complete, None if last_ns is None else last_ns / 1e9)
