"""Thread budgets: the cores this process may use, and BLAS / OpenMP / OpenCV threads bounded per stage.

Every stage states the parallelism it really uses and holds the libraries under it, so that CPU time
/ wall time never exceeds it:
  * detection: N worker processes, each with one OpenCV and one BLAS thread (``limit_this_process``,
    ``core.capture.worker_pool``); on threads, OpenCV on one thread for the run;
  * solves, held-out validation folds, the rig and hand-eye LMs: OpenCV and BLAS on one thread
    (``single_threaded``, which ``core.intrinsics.solution.single_threaded_opencv`` and every solve, the
    capture gates' lens fit, ``solve_rig`` and ``fit_handeye`` enter), parallel only on the verdict lanes
    (``core.lanes``: the workflow's pool of ``--jobs`` - 1 threads and the caller, inside one block around the
    pool: the held-out folds, the one-camera test beside the other gates and its groups, the lens floor).

The libraries are found and set by threadpoolctl (every loaded OpenBLAS, MKL, BLIS and OpenMP runtime:
opencv-python's bundled OpenBLAS and numpy's scipy-openblas on the wheels we ship), not by hand.

Why BLAS on one thread: opencv-python's OpenBLAS worker thread spins on a second core whenever a solve
runs and for ~0.1 s after it, even with cv2.setNumThreads(1) and matrices far too small to share out
(2 cores, OpenCV 5.0.0: one solve_intrinsics of 20 views cost 22 ms wall and 44 ms CPU; the 5-fold
held-out validation of 20 views at 1280x960 took 200-350 ms on 2 threads against 87-90 ms with
OpenBLAS on one thread, results identical to the bit: at these sizes OpenBLAS computes on the calling
thread whatever its thread count, the count only decides who spins).

The limits are process-global, like cv2.setNumThreads: enter a block once around a whole thread pool, on the
thread that owns the pool (an OpenBLAS limit set from another thread was seen not to take), not in each task;
blocks opened inside it cost a counter (``_OneThreadBlas``).

A command that never solves (``lint``) does better still: its OpenBLAS never starts the worker threads
at all (``blas_starts_on_one_thread``, around the first import of numpy or cv2); threadpoolctl can only
change a library already loaded. numpy's OpenBLAS starts one thread per core when it loads, and they
spin before they sleep: ``import numpy`` took 180 ms of CPU with them and 110 with OPENBLAS_NUM_THREADS=1
(benchmarks/results/startup.md).
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from threadpoolctl import ThreadpoolController

OPENBLAS_THREADS_ENV = "OPENBLAS_NUM_THREADS"


def available_cores() -> int:
    """The CPUs this process may run on (its affinity mask: taskset, cgroup cpusets), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # macOS, Windows
        return max(1, os.cpu_count() or 1)


@functools.cache
def _controller() -> ThreadpoolController:
    """The BLAS / OpenMP libraries of this process, found once (2 ms; a limit then costs 0.1 ms). Called
    from code that has imported numpy and cv2, so their libraries are loaded by then."""
    from threadpoolctl import ThreadpoolController  # here: lint and --help never load it

    return ThreadpoolController()


class _OneThreadBlas:
    """The process-wide count of open ``single_threaded_blas`` blocks, on every thread: the first to open sets
    the limit, the last to close restores it. Blocks nest under the workflow's (verdict_lanes) thousands of
    times per ``calibrate`` (every pose refit enters one), and a threadpoolctl limit and restore costs ~0.1 ms
    even when the libraries are at one thread already: 2711 of them were 0.3 s of CPU at 96 views."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._open = 0
        self._limiter: contextlib.AbstractContextManager[object] | None = None

    def enter(self) -> None:
        with self._lock:
            if self._open == 0:
                limiter = _controller().limit(limits=1)
                limiter.__enter__()
                self._limiter = limiter
            self._open += 1

    def leave(self) -> None:
        with self._lock:
            self._open -= 1
            if self._open == 0 and self._limiter is not None:
                limiter, self._limiter = self._limiter, None
                limiter.__exit__(None, None, None)


_ONE_THREAD_BLAS = _OneThreadBlas()


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Every loaded BLAS and OpenMP runtime on one thread inside the block, restored when the last open block
    (on any thread) closes; a block inside another costs a counter, not a library call."""
    _ONE_THREAD_BLAS.enter()
    try:
        yield
    finally:
        _ONE_THREAD_BLAS.leave()


@contextlib.contextmanager
def single_threaded() -> Iterator[None]:
    """OpenCV and every loaded BLAS / OpenMP runtime on one thread inside the block, restored afterwards:
    a stage that solves on the calling thread alone (the capture gates, a solve, an LM), with results
    that do not depend on the machine's core count. OpenCV's count is left alone when it is 1 already,
    so a nested block leaving never gives OpenCV its threads back under an enclosing one."""
    import cv2

    previous = cv2.getNumThreads()
    if previous != 1:
        cv2.setNumThreads(1)
    try:
        with single_threaded_blas():
            yield
    finally:
        if previous != 1:
            cv2.setNumThreads(previous)


def limit_this_process(threads: int) -> None:
    """OpenCV and every loaded BLAS / OpenMP runtime on ``threads`` threads for the rest of the process
    (a worker process's initializer)."""
    import cv2

    cv2.setNumThreads(threads)
    _controller().limit(limits=threads)


def thread_counts() -> dict[str, int]:
    """The thread count of OpenCV and of every loaded BLAS / OpenMP library, by file name (for checks and
    benchmarks: what a stage really runs on)."""
    import cv2
    from threadpoolctl import threadpool_info

    counts = {"opencv": int(cv2.getNumThreads())}
    counts.update({Path(lib["filepath"]).name: int(lib["num_threads"]) for lib in threadpool_info()})
    return counts


@contextlib.contextmanager
def blas_starts_on_one_thread() -> Iterator[None]:
    """An OpenBLAS that loads inside the block (numpy's or cv2's, at their first import) starts on one thread.

    For a process that never solves: OpenBLAS reads its thread count once, when it loads, so a library
    already loaded keeps its threads. The variable is restored on leaving (a child process, or a library
    loaded later, starts as it always did), and a count the user set is left as it is.
    """
    if OPENBLAS_THREADS_ENV in os.environ:
        yield
        return
    os.environ[OPENBLAS_THREADS_ENV] = "1"
    try:
        yield
    finally:
        del os.environ[OPENBLAS_THREADS_ENV]
