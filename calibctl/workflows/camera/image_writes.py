"""A folder capture's images written into the store on a thread of their own, beside the capture gates.

Storing a folder's images (``Store.put_images``: every file written and fsynced, then the rows of
``IMAGE_BATCH`` images in one transaction) waits on the disk, and the gates that follow are solves
(``workflows.camera.capture._build_session``): file I/O and fsync release the GIL, so the writes run on
one thread of their own while the gates compute. It is a thread for waiting, not a ``--jobs`` lane:
hashing the bytes is its only computation. What does not change:

  * the images are durable before anything names them: the capture waits for the writes (``stored``)
    before its session is stored or handed on (a rig's members, the station's spool);
  * failures read as in the sequential order, where the writes came first: their failure (a full disk, an
    image folder that cannot be written, a file changed since it was read) is the one raised, exit 2 with
    no session stored; the gates' own failure only when the writes got through (``after``);
  * Ctrl-C during the gates: the writes stop after the batch in progress (a batch is one transaction,
    all of its rows or none; files without rows are unreferenced and expire) and the session is not stored.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Executor

from calibctl.core.lanes import Deferred, Lanes


class ImageWrites:
    """``write(stop)`` started on ``writer`` (a one-thread pool the capture owns); ``write`` returns the
    number of images stored and checks ``stop`` between batches."""

    def __init__(self, writer: Executor, write: Callable[[threading.Event], int]) -> None:
        self._stop = threading.Event()
        self._done: Deferred[int] = Lanes(writer).start(lambda: write(self._stop))

    def stored(self) -> int:
        """Wait until every image is durable; how many were stored (the writes' error raised). Ctrl-C while
        waiting stops them as during the gates (``after``)."""
        try:
            return self._done.result()
        except KeyboardInterrupt as interrupt:
            self.after(interrupt)
            raise

    def after(self, failure: BaseException) -> None:
        """The gates failed with ``failure``, about to be raised. Ctrl-C: stop after the batch in progress
        and wait for it. Otherwise let the writes finish, as they had in the sequential order, and raise
        their own error if they fail (that order met it first)."""
        if isinstance(failure, KeyboardInterrupt):
            self._stop.set()
            self._done.settle()
            return
        self._done.result()
