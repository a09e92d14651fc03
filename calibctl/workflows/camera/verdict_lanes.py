"""The pool the verdict stages of capture and solve share: ``--jobs`` lanes, OpenCV and BLAS on one thread
each.

``calibrate``'s verdicts beyond the plain script's one solve are independent solves (the one-camera split
test beside the held-out folds and the lens floor, the split test's two groups, the folds themselves);
core takes them as ``core.lanes.Lanes``, this module owns the threads. ``jobs`` lanes are the calling
thread and ``jobs - 1`` pool threads, so the process never computes on more than ``jobs`` threads, and
every library is held to one thread for the pool's whole life (``core.blas_threads.single_threaded``: the
limits are process-global, so they are entered once around the pool, not per task). ``jobs`` 1 is the
plain sequential loop. The numbers and verdicts are the same at every job count
(tests/workflows/camera/test_verdict_lanes.py).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

from calibctl.core.blas_threads import single_threaded
from calibctl.core.lanes import Lanes


@contextlib.contextmanager
def verdict_lanes(jobs: int) -> Iterator[Lanes]:
    """``jobs`` lanes (at least one) for the verdict stages inside the block; the pool is shut down on
    leaving."""
    with single_threaded():
        if jobs <= 1:
            yield Lanes()
            return
        with ThreadPoolExecutor(max_workers=jobs - 1, thread_name_prefix="calibctl-verdicts") as pool:
            yield Lanes(pool)
