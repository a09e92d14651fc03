"""Thread budgets: the cores this process may use, and BLAS / OpenMP / OpenCV threads bounded per stage.

Every stage states the parallelism it really uses and holds the libraries under it, so that CPU time
/ wall time never exceeds it:
  * detection: N worker processes, each with one OpenCV and one BLAS thread (``limit_this_process``,
    ``core.capture.worker_pool``); on threads, OpenCV on one thread for the run;
  * solves, held-out validation folds, the rig and hand-eye LMs: OpenCV and BLAS on one thread
    (``single_threaded``, which ``core.intrinsics.solution.single_threaded_opencv`` and every solve, the
    capture gates' lens fit, ``solve_rig`` and ``fit_handeye`` enter), parallel only where the stage
    itself runs folds or pairs on Python threads (validation folds, the one-camera test's pairs).

The libraries are found and set by threadpoolctl (every loaded OpenBLAS, MKL, BLIS and OpenMP runtime:
opencv-python's bundled OpenBLAS and numpy's scipy-openblas on the wheels we ship), not by hand.

Why BLAS on one thread: opencv-python's OpenBLAS worker thread spins on a second core whenever a solve
runs and for ~0.1 s after it, even with cv2.setNumThreads(1) and matrices far too small to share out
(2 cores, OpenCV 5.0.0: one solve_intrinsics of 20 views cost 22 ms wall and 44 ms CPU; the 5-fold
held-out validation of 20 views at 1280x960 took 200-350 ms on 2 threads against 87-90 ms with
OpenBLAS on one thread, results identical to the bit: at these sizes OpenBLAS computes on the calling
thread whatever its thread count, the count only decides who spins).

The limits are process-global, like cv2.setNumThreads: enter a block once around a whole thread pool,
not in each task.

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


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Every loaded BLAS and OpenMP runtime on one thread inside the block, restored afterwards."""
    with _controller().limit(limits=1):
        yield


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
