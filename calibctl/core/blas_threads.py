"""OpenBLAS on one thread for a block of code: what lets Python threads solve in parallel.

opencv-python bundles its own OpenBLAS (opencv_python_headless.libs/libopenblasp-r0-*.so, 0.3.15,
pthreads), which OpenCV's LAPACK calls inside calibrateCamera use; numpy bundles another
(scipy-openblas). Measured on the bench machine (2 cores, OpenCV 5.0.0): OpenCV's OpenBLAS worker
thread spins on the second core whenever a solve runs and for ~0.1 s after it, even with
cv2.setNumThreads(1) and with matrices far too small to share out. One solve_intrinsics of 20 views
costs 22 ms wall but 44 ms CPU. Two Python threads solving held-out folds at once then compete with
that spinning thread for the 2 cores: the 5-fold held-out validation of 20 views at 1280x960 took
200-350 ms on 2 threads against 150-180 ms on one. With OpenBLAS on one thread (OPENBLAS_NUM_THREADS=1
before start-up) it took 87-90 ms on 2 threads and 117-163 ms on one, with results identical to the
bit (tests/core/intrinsics/test_validation.py; at these sizes OpenBLAS computes on the calling thread whatever its
thread count, the count only decides who spins).

The thread count is process-global, like cv2.setNumThreads: enter the block once around a whole thread
pool, not in each task. An OpenBLAS that cannot be found (another wheel layout, another BLAS) is left
alone: the block then changes nothing, and only the speed differs.

A command that never solves (``lint``) does better still: its OpenBLAS never starts the
worker threads at all (``blas_starts_on_one_thread``, around the first import of numpy or cv2). numpy's
OpenBLAS starts one per core when it loads, and they spin before they sleep: ``import numpy`` took 180 ms
of CPU with them and 110 with OPENBLAS_NUM_THREADS=1 (BENCHMARKS.md section 12).
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections.abc import Callable, Iterator
from pathlib import Path

# (set, get) symbol pairs: numpy >= 2 wheels bundle scipy-openblas (64-bit ints, prefixed symbols);
# opencv-python's copy and system builds export OpenBLAS's own names.
_SYMBOLS = (("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
            ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
            ("openblas_set_num_threads", "openblas_get_num_threads"))
_PACKAGES = ("cv2", "numpy")
_WHEEL_LIB_DIRS = ("opencv_python_headless.libs", "opencv_python.libs", "opencv_contrib_python.libs",
                   "opencv_contrib_python_headless.libs", "numpy.libs")

Threads = tuple[Callable[[int], None], Callable[[], int]]  # (set, get)


def _candidates() -> list[Path]:
    """Bundled OpenBLAS files of the opencv-python and numpy wheels (Linux/Windows: <pkg>.libs beside
    the package; macOS: <pkg>/.dylibs)."""
    from importlib.util import find_spec

    found: list[Path] = []
    for package in _PACKAGES:
        spec = find_spec(package)
        if spec is None or spec.origin is None:
            continue
        package_dir = Path(spec.origin).resolve().parent
        for lib_dir in (*(package_dir.parent / name for name in _WHEEL_LIB_DIRS), package_dir / ".dylibs"):
            found += sorted(lib_dir.glob("*openblas*"))
    return list(dict.fromkeys(found))


@functools.cache
def _openblas_threads() -> tuple[Threads, ...]:
    """(set, get) for every bundled OpenBLAS that can be found."""
    import ctypes  # here, not at the top: blas_starts_on_one_thread runs before anything is loaded

    out: list[Threads] = []
    for path in _candidates():
        try:
            lib = ctypes.CDLL(str(path))  # already loaded by cv2 / numpy: this returns the same library
        except OSError:
            continue
        for set_name, get_name in _SYMBOLS:
            if hasattr(lib, set_name) and hasattr(lib, get_name):
                setter, getter = getattr(lib, set_name), getattr(lib, get_name)
                setter.argtypes, setter.restype = [ctypes.c_int], None
                getter.argtypes, getter.restype = [], ctypes.c_int
                out.append((setter, getter))
                break
    return tuple(out)


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run the bundled OpenBLAS copies on one thread inside the block, restore their counts afterwards."""
    changed = [(setter, getter()) for setter, getter in _openblas_threads() if getter() != 1]
    for setter, _ in changed:
        setter(1)
    try:
        yield
    finally:
        for setter, previous in changed:
            setter(previous)


OPENBLAS_THREADS_ENV = "OPENBLAS_NUM_THREADS"


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
