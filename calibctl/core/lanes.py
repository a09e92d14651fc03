"""Lanes: independent solves run at once on a pool the caller owns, with the numbers of a sequential run.

The verdicts behind ``calibrate`` (held-out folds, the one-camera split test's two groups, the lens floor's
models, the capture gates beside the split test) are independent solves, and cv2.calibrateCamera releases
the GIL, so they can share the cores on Python threads. Core functions take a ``Lanes`` (or None: one
lane, the plain sequential loop); the workflow owns the pool and the thread limits:

  * ``Lanes(pool)``: the calling thread is one lane and the pool's workers the others, so ``jobs`` lanes are
    a pool of ``jobs - 1`` threads. A task no worker has started yet when the caller needs its result is
    run by the caller itself (``Future.cancel`` succeeds only on a task not started), so a lane waiting on
    nested work never waits on a queue: a bounded pool cannot deadlock, whatever the nesting (the split test
    maps its groups from inside a lane), and with every worker busy the run degrades to the sequential loop.
  * the numbers do not depend on the lane count: every solve runs with OpenCV and BLAS on one thread
    (``core.blas_threads.single_threaded``, entered by the pool's owner around the whole pool because the
    counts are process-global) and each result is collected by its index, reduced in input order;
  * errors are those of the sequential loop: the first failing item in input order raises, after the
    items already started have finished (nothing runs on once the caller has moved on).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future
from typing import Generic, TypeVar

T = TypeVar("T")
R = TypeVar("R")


class Deferred(Generic[R]):
    """A result started on a lane; ``result()`` runs it on the caller when no worker has started it."""

    def __init__(self, future: Future[R] | None, work: Callable[[], R]) -> None:
        self._future, self._work = future, work

    def result(self) -> R:
        if self._future is None or self._future.cancel():
            return self._work()
        return self._future.result()

    def settle(self) -> None:
        """Cancel it if not started, else wait for it (its error, if any, is not raised)."""
        if self._future is not None and not self._future.cancel():
            self._future.exception()


class Lanes:
    """``jobs`` lanes: the caller plus ``pool``'s workers (module docstring). ``Lanes(None)``: one lane."""

    def __init__(self, pool: Executor | None = None) -> None:
        self._pool = pool

    def start(self, work: Callable[[], R]) -> Deferred[R]:
        """``work`` offered to a free worker now; its result taken (or computed here) by ``result()``."""
        return Deferred(None if self._pool is None else self._pool.submit(work), work)

    def map(self, work: Callable[[T], R], items: Sequence[T]) -> list[R]:
        """[work(item) for item in items], the items spread over the lanes, the first error in order
        raised."""
        if self._pool is None or len(items) < 2:
            return [work(item) for item in items]
        # the caller takes the first item itself; the others are offered to the workers
        rest = [self.start(_bound(work, item)) for item in items[1:]]
        out: list[R] = []
        try:
            out.append(work(items[0]))
            for deferred in rest:
                out.append(deferred.result())
        except BaseException:
            for deferred in rest[len(out) :]:
                deferred.settle()
            raise
        return out


def lanes_map(lanes: Lanes | None, work: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``lanes.map``, or the sequential loop when ``lanes`` is None."""
    return (lanes or Lanes()).map(work, items)


def _bound(work: Callable[[T], R], item: T) -> Callable[[], R]:
    return lambda: work(item)
