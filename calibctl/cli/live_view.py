"""What the operator sees on stderr while a capture runs: a progress bar for folders, a live view for streams.

The live view (rich Live) shows the 3x3 image-region coverage, the tilt directions collected (a compass
of the board side that is farther from the camera), the observability gauge against its threshold on a
log scale, the view count, and what is still missing in words (the gates' hints). Both are drawn only
when stderr is a terminal and the output is not JSON. Otherwise (a log file, a pipe, a CI job, --json)
``LogObserver`` writes one plain progress line when the capture starts and then at most one every
``PROGRESS_EVERY_S`` seconds, so a long run is visibly alive without flooding the log.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from collections.abc import Callable
from types import TracebackType

from rich.console import Group, RenderableType
from rich.live import Live
from rich.panel import Panel
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn, TimeElapsedColumn
from rich.table import Table
from rich.text import Text

from calibctl.cli.render import stderr
from calibctl.workflows.camera.capture import CaptureObserver, FrameDecision, SelectionProgress

PROGRESS_EVERY_S = 5.0
GAUGE_WIDTH = 24
GAUGE_DECADES_BELOW = 2.0  # the gauge spans threshold / 100 .. threshold * 10
GAUGE_DECADES_ABOVE = 1.0
# (row, col) of each tilt direction on a 3x3 compass, and its arrow
_COMPASS = {
    "top left": (0, 0, "↖"),
    "top": (0, 1, "↑"),
    "top right": (0, 2, "↗"),
    "left": (1, 0, "←"),
    "right": (1, 2, "→"),
    "bottom left": (2, 0, "↙"),
    "bottom": (2, 1, "↓"),
    "bottom right": (2, 2, "↘"),
}


def coverage_grid(covered: tuple[tuple[bool, ...], ...]) -> Text:
    """3 lines of 3 cells: a filled square where corners reached that cell of the image."""
    text = Text()
    for r, row in enumerate(covered):
        for c, hit in enumerate(row):
            text.append("■" if hit else "□", style="green" if hit else "dim")
            if c < len(row) - 1:
                text.append(" ")
        if r < len(covered) - 1:
            text.append("\n")
    return text


def direction_compass(directions: tuple[str, ...]) -> Text:
    """3 lines: an arrow for each tilt direction collected, a dot for the others."""
    cells = [["·", "·", "·"] for _ in range(3)]
    styles = [["dim"] * 3 for _ in range(3)]
    cells[1][1], styles[1][1] = "○", "dim"
    for name in directions:
        if name in _COMPASS:
            r, c, arrow = _COMPASS[name]
            cells[r][c], styles[r][c] = arrow, "green"
    text = Text()
    for r in range(3):
        for c in range(3):
            text.append(cells[r][c], style=styles[r][c])
            if c < 2:
                text.append(" ")
        if r < 2:
            text.append("\n")
    return text


def observability_gauge(value: float, threshold: float, width: int = GAUGE_WIDTH) -> Text:
    """A log-scale bar from threshold/100 to threshold*10 with a '|' at the threshold."""
    low = math.log10(threshold) - GAUGE_DECADES_BELOW
    span = GAUGE_DECADES_BELOW + GAUGE_DECADES_ABOVE
    filled = 0 if value <= 0 else round(min(1.0, max(0.0, (math.log10(value) - low) / span)) * width)
    mark = round(GAUGE_DECADES_BELOW / span * width)
    ok = value >= threshold
    text = Text("[")
    for i in range(width):
        if i == mark:
            text.append("|", style="bold")
        text.append("█" if i < filled else "░", style=("green" if ok else "yellow") if i < filled else "dim")
    text.append("] ")
    text.append(f"{value:.1e}", style="green" if ok else "yellow")
    text.append(f" (need {threshold:.0e})")
    return text


CTRL_C_KEEPS = "Ctrl-C: stop and keep what was captured"


def live_panel(
    progress: SelectionProgress,
    last: FrameDecision | None,
    frames: int,
    t_s: float,
    min_views: int,
    max_views: int | None,
    ctrl_c: str = CTRL_C_KEEPS,
) -> RenderableType:
    """The live view's content for one moment of the capture."""
    top = Table.grid(padding=(0, 4))
    for _ in range(3):
        top.add_column()
    top.add_row(
        Text("coverage", style="bold"),
        Text("tilt directions", style="bold"),
        Text("observability", style="bold"),
    )
    top.add_row(
        coverage_grid(progress.covered),
        direction_compass(progress.directions),
        observability_gauge(progress.observability, progress.observability_min),
    )
    target = f" (stop at {max_views})" if max_views is not None else ""
    status = Text(f"views {progress.n_views}, need {min_views}{target}   frames {frames}   {t_s:.1f} s")
    parts: list[RenderableType] = [top, status]
    if progress.missing:
        parts.append(Text("still missing:", style="bold"))
        parts += [Text(f"  - {hint}", style="yellow") for hint in progress.missing]
    else:
        parts.append(Text("every gate passes", style="green"))
    if last is not None:
        parts.append(
            Text(
                f"last: {last.name} {last.status}: {last.reason}",
                style="green" if last.kept else "dim",
                overflow="ellipsis",
                no_wrap=True,
            )
        )
    return Panel(Group(*parts), title="calibctl capture", subtitle=ctrl_c)


class TerminalObserver(CaptureObserver):
    """Draws the folder progress bar or the stream live view on stderr; use as a context manager."""

    def __init__(self, min_views: int, max_views: int | None, ctrl_c: str = CTRL_C_KEEPS) -> None:
        self.min_views = min_views
        self.max_views = max_views
        self.ctrl_c = ctrl_c
        self._progress: Progress | None = None
        self._task: TaskID | None = None
        self._live: Live | None = None
        self._frames = 0

    def folder_started(self, total: int) -> None:
        self._progress = Progress(
            TextColumn("detecting"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[name]}"),
            console=stderr,
            transient=True,
        )
        self._task = self._progress.add_task("detect", total=total, name="")
        self._progress.start()

    def image_done(self, done: int, total: int, name: str, status: str) -> None:
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=done, name=f"{name}: {status}")

    def frame_done(self, decision: FrameDecision, progress: SelectionProgress, t_s: float) -> None:
        self._frames += 1
        panel = live_panel(progress, decision, self._frames, t_s, self.min_views, self.max_views, self.ctrl_c)
        if self._live is None:
            self._live = Live(panel, console=stderr, refresh_per_second=8, transient=False)
            self._live.start()
        else:
            self._live.update(panel)

    def __enter__(self) -> TerminalObserver:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._progress is not None:
            self._progress.stop()
        if self._live is not None:
            self._live.stop()


class LogObserver(CaptureObserver):
    """Plain progress lines on stderr for logs and pipes: at the start, then at most every ``every_s``."""

    def __init__(
        self, min_views: int, every_s: float = PROGRESS_EVERY_S, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.min_views = min_views
        self.every_s = every_s
        self._clock = clock
        self._start = self._last = clock()
        self._statuses: Counter[str] = Counter()
        self._frames = 0

    def _due(self) -> float | None:
        """Seconds since the start when a line is due, else None."""
        now = self._clock()
        if now - self._last < self.every_s:
            return None
        self._last = now
        return now - self._start

    @staticmethod
    def _line(text: str) -> None:
        print(f"calibctl capture: {text}", file=sys.stderr, flush=True)

    def folder_started(self, total: int) -> None:
        self._line(
            f"examining {total} images (a progress line every {self.every_s:g} s; Ctrl-C stops, "
            "nothing is stored)"
        )

    def image_done(self, done: int, total: int, name: str, status: str) -> None:
        self._statuses[status] += 1
        elapsed = self._due()
        if elapsed is not None:
            counts = ", ".join(f"{n} {s}" for s, n in self._statuses.most_common())
            self._line(f"{done} of {total} images examined ({counts}), {elapsed:.0f} s")

    def frame_done(self, decision: FrameDecision, progress: SelectionProgress, t_s: float) -> None:
        self._frames += 1
        if self._frames == 1:  # the stream is open and delivering: said once, as a folder's start is
            self._line(
                f"frames arriving, {progress.n_views} views kept of {self.min_views} needed (a progress line "
                f"every {self.every_s:g} s)"
            )
        elapsed = self._due()
        if elapsed is not None:
            missing = f"; missing: {progress.missing[0]}" if progress.missing else "; every gate passes"
            self._line(
                f"{self._frames} frames, {progress.n_views} views kept (need {self.min_views}), "
                f"stream time {t_s:.1f} s{missing}"
            )

    def __enter__(self) -> LogObserver:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        return None


def capture_observer(
    as_json: bool, min_views: int, max_views: int | None, ctrl_c: str = CTRL_C_KEEPS
) -> TerminalObserver | LogObserver:
    """The live terminal observer when stderr is a terminal and the output is not JSON, else progress lines.
    ``ctrl_c``: what the live view says Ctrl-C does (the station cancels the unit)."""
    if as_json or not stderr.is_terminal:
        return LogObserver(min_views)
    return TerminalObserver(min_views, max_views, ctrl_c)
