"""Pictures arriving one by one in a folder: when each is complete, and its detection started as it lands.

A camera app writes a unit's pictures into the unit's folder while the operator moves the board.
``Arrivals.poll`` lists the folder's image files (``image_outcomes.IMAGE_SUFFIXES``, as a folder capture
lists them) and says which are newly complete. The rule, per file:

  * ``settle_s`` 0: complete when seen. Only for an app that writes each picture under another name
    (``shot.png.part``, ``.tmp``: not an image by its suffix, so never listed) and renames it into place;
    a rename is atomic, so a listed file is whole.
  * ``settle_s`` > 0: complete when its size, mtime, ctime and inode stayed the same for ``settle_s``
    seconds of polls (an app that writes in place). A file that changes after it was judged complete
    is judged again, as a new arrival.

``EarlyDetections`` starts each complete file's detection at once (``image_outcomes.start_file``: the
warm process pool, or this thread at one job) and later answers ``classify_files(known=...)`` with it
only while the file still has the signature it was detected with: a file rewritten since is detected
again, so early outcomes are exactly what a batch capture of the folder gives.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import image_outcomes as outcomes_core

Signature = tuple[int, int, int, int]  # size bytes, mtime ns, ctime ns, inode
Detected = tuple[outcomes_core.ImageOutcome, object]  # the outcome and ``summarize`` of its pixels


def signature(path: Path) -> Signature | None:
    """What identifies one version of a file (None: it is gone)."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino


@dataclass
class _Seen:
    signature: Signature
    since_s: float  # clock time the file was first seen with this signature
    complete: bool = False


class Arrivals:
    """The image files of one folder and which of them are complete (see the module docstring)."""

    def __init__(self, folder: Path, settle_s: float) -> None:
        self.folder, self.settle_s = folder, settle_s
        self._files: dict[Path, _Seen] = {}

    def poll(self, now_s: float) -> list[tuple[Path, Signature]]:
        """The files that became complete since the last poll, in name order (``now_s``: a monotonic
        clock)."""
        try:
            listed = set(outcomes_core.list_images(self.folder))  # the files a folder capture will read
        except FileNotFoundError:  # the camera app has not made the unit's folder yet
            listed = set()
        for gone in set(self._files) - listed:
            del self._files[gone]
        newly = []
        for path in sorted(listed):
            sig = signature(path)
            if sig is None:
                continue
            seen = self._files.get(path)
            if seen is None or seen.signature != sig:  # new, or written to since: its settle time starts now
                seen = self._files[path] = _Seen(sig, now_s)
            if not seen.complete and now_s - seen.since_s >= self.settle_s:
                seen.complete = True
                newly.append((path, sig))
        return newly

    @property
    def complete(self) -> int:
        return sum(1 for s in self._files.values() if s.complete)

    @property
    def pending(self) -> int:
        """Image files listed but not complete yet (being written, or settling)."""
        return sum(1 for s in self._files.values() if not s.complete)

    def last_in_ns(self) -> int | None:
        """When the last complete file landed: its ctime (the last write or the rename into place), epoch
        ns."""
        times = [s.signature[2] for s in self._files.values() if s.complete]
        return max(times) if times else None


class EarlyDetections:
    """Each complete file's detection, started as it lands; the ``known`` answer of ``classify_files``."""

    def __init__(
        self, spec: BoardSpec, workers: int, summarize: outcomes_core.Summarize | None = None
    ) -> None:
        self.spec, self.workers, self.summarize = spec, workers, summarize
        self._started: dict[Path, tuple[Signature, Future[Detected]]] = {}

    def start(self, path: Path, sig: Signature) -> None:
        self._started[path] = (
            sig,
            outcomes_core.start_file(path, self.spec, self.workers, summarize=self.summarize),
        )

    def futures(self) -> list[Future[Detected]]:
        return [future for _, future in self._started.values()]

    def cancel(self) -> None:
        """Drop the detections not started yet (Ctrl-C, a timeout); running ones end in their worker."""
        for _, future in self._started.values():
            future.cancel()

    def known(self, path: Path) -> Detected | None:
        """The early outcome of ``path`` if it is done and the file is still the version detected, else
        None."""
        started = self._started.get(Path(path))
        if started is None or not started[1].done() or started[1].cancelled():
            return None
        sig, future = started
        if future.exception() is not None or signature(Path(path)) != sig:
            return None
        return future.result()

    def for_spec(
        self, spec: BoardSpec, summarize: outcomes_core.Summarize | None
    ) -> Callable[[Path], Detected | None] | None:
        """``known`` when detection used ``spec`` (the capture's board) and ``summarize``, else None: detect
        it all again."""
        return self.known if spec == self.spec and summarize is self.summarize else None
