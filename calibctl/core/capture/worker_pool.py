"""The warm pool of detection processes: started once per calibctl process, reused by every capture.

Why processes: OpenCV releases the GIL inside its calls, but the Python between them (grid checks,
canonical order, blur profiles, hashing) does not, so threads stop scaling after two or three
(``image_outcomes.choose_executor`` has the numbers). Why a warm pool: starting one costs ~0.3 s on 2
cores (an interpreter that imports numpy and OpenCV); a station that captures unit after unit pays it
once, and each later capture forks nothing.

Start method: forkserver where available, else spawn; never plain fork. Forking a process whose OpenCV
thread pool has run (any earlier cv2 call in this process) copies its locked mutexes and deadlocks the
child. The fork server is a fresh process that only imports the detection modules, so workers forked
from it start quickly and safely; it lives as long as the calibctl process. Like every non-fork start
method it needs the ``if __name__ == "__main__":`` guard in scripts.

Each worker runs OpenCV and its BLAS libraries on one thread (``blas_threads.limit_this_process``): N
workers use N cores, never N x cores, and the corners are bit-identical to a one-thread run.

Ctrl-C reaches the whole process group, and only the calibctl process decides what it means (cancel
the queued files, keep the pool, store nothing). So the fork server is started with SIGINT
ignored, which it and every worker it forks inherit from their first instruction on (a Ctrl-C that
landed in a half-started fork server made the launch fail with "EOFError: unexpected EOF"), and the
pool's processes are launched with Ctrl-C held back until the launch is done (``shielded``; one that
landed inside ``submit`` left the pool with a dead fork server: "ConnectionRefusedError").

Results come back through a file, not the pool's pipe (``submit``). ProcessPoolExecutor's manager thread
reads a result once the pipe has data and then blocks until the whole message is there: a worker killed
(out-of-memory killer) half-way through writing a result hangs the caller for good instead of raising
BrokenProcessPool. A detection result carries the half-size picture (~300 KB at 1280x960), larger than
the pipe's buffer; killing a worker at random moments of such a stream hung 12 to 18 of 30 runs (CPython
3.11, ``benchmarks/stress_pool_kill.py``). So a worker writes its pickled result into a private
folder and sends only the file's name, a message far below PIPE_BUF, which the kernel writes whole or
not at all; unpickling that name in the caller reads the file back (``_load_result``), so every
``Future`` holds the real result.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing
import os
import pickle
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from types import FrameType
from typing import Any, TypeVar

from calibctl.core.blas_threads import available_cores, limit_this_process

__all__ = [
    "available_cores",
    "discard_if_broken",
    "is_warm",
    "process_pool",
    "shielded",
    "shutdown_pool",
    "start_server",
    "submit",
    "warm",
]

R = TypeVar("R")

_lock = threading.Lock()
_pool: ProcessPoolExecutor | None = None
_pool_workers = 0
_results_dir: str | None = None  # this process's folder of results in flight, removed at exit


def _init_worker() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    limit_this_process(1)


def _mp_context() -> multiprocessing.context.BaseContext:
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["calibctl.core.capture.image_outcomes"])
        return ctx
    return multiprocessing.get_context("spawn")


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """Ctrl-C held back inside the block (a launch is never interrupted half-way) and acted on when it
    ends: this thread's SIGINT handler records it, then the previous handler runs (KeyboardInterrupt for
    Python's own; the station's may hold it). A no-op off the main thread, where handlers cannot be set."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[tuple[int, FrameType | None]] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: came.append((signum, frame)))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if came:
            if callable(previous):
                previous(*came[0])
            elif previous != signal.SIG_IGN:
                raise KeyboardInterrupt


@contextlib.contextmanager
def _safe_path() -> Iterator[None]:
    """``PYTHONSAFEPATH`` set while the fork server and the resource tracker start: they run ``python -c``,
    which would put the working folder first on ``sys.path``, and the server's imports (cached in every worker
    it forks) would then take a ``calibctl/`` folder, a ``cv2.py`` or a ``numpy/`` there for the installed
    packages."""
    before = os.environ.get("PYTHONSAFEPATH")
    os.environ["PYTHONSAFEPATH"] = "1"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("PYTHONSAFEPATH", None)
        else:
            os.environ["PYTHONSAFEPATH"] = before


@contextlib.contextmanager
def _started_ignoring_sigint() -> Iterator[None]:
    """SIGINT ignored while the fork server and the resource tracker are started: an ignored signal stays
    ignored across exec, so they start (and import OpenCV) immune to Ctrl-C, and the fork server hands the
    ignored SIGINT on to every worker it forks. A Ctrl-C in these few milliseconds is lost."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def start_server() -> None:
    """Start the fork server now and return at once: it imports OpenCV and the detection modules on another
    core while this process goes on (a fresh ``capture`` importing its store and workflow), so the pool's
    first workers fork from a ready server instead of waiting ~0.2 s for it. A no-op where there is no fork
    server (spawn)."""
    with _lock:
        _ensure_server(_mp_context())


def _ensure_server(ctx: multiprocessing.context.BaseContext) -> None:
    if ctx.get_start_method() == "forkserver":
        from multiprocessing import forkserver

        with _started_ignoring_sigint(), _safe_path():
            # and the resource tracker; returns before the server's imports are done
            forkserver.ensure_running()


def process_pool(workers: int) -> ProcessPoolExecutor:
    """The process-wide pool of ``workers`` detection processes (a pool of another size is replaced)."""
    global _pool, _pool_workers
    with _lock:
        if _pool is None or _pool_workers != workers:
            if _pool is not None:
                _pool.shutdown(wait=False, cancel_futures=True)
            ctx = _mp_context()
            _ensure_server(ctx)
            _pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker)
            _pool_workers = workers
        return _pool


def submit(pool: ProcessPoolExecutor, fn: Callable[..., R], *args: Any) -> Future[R]:
    """``pool.submit(fn, *args)`` with the result handed back through a file (the module docstring says
    why)."""
    return pool.submit(_run_to_file, _results_folder(), fn, *args)


def _results_folder() -> str:
    """The folder this process's workers write results into: in memory (/dev/shm) where there is one."""
    global _results_dir
    with _lock:
        if _results_dir is None or not os.path.isdir(_results_dir):
            shm = "/dev/shm"
            where = shm if os.path.isdir(shm) and os.access(shm, os.W_OK | os.X_OK) else None
            _results_dir = tempfile.mkdtemp(prefix="calibctl-results-", dir=where)
            atexit.register(shutil.rmtree, _results_dir, True)  # and what a killed worker left half-written
        return _results_dir


class _ResultFile:
    """A worker's result written to ``path``: pickles as a call that reads it back (and removes the file)."""

    __slots__ = ("path",)

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self) -> tuple[Callable[[str], Any], tuple[str]]:
        return _load_result, (self.path,)


def _run_to_file(folder: str, fn: Callable[..., Any], *args: Any) -> Any:
    """In a worker: ``fn(*args)`` pickled into ``folder``; the result itself when that cannot be written
    (no space, the folder gone): through the pipe as ProcessPoolExecutor sends it."""
    result = fn(*args)
    try:
        fd, path = tempfile.mkstemp(dir=folder, suffix=".pickle")
    except OSError:
        return result
    try:
        with os.fdopen(fd, "wb") as f:
            pickle.dump(result, f, protocol=pickle.HIGHEST_PROTOCOL)
    except OSError:
        with contextlib.suppress(OSError):
            os.unlink(path)
        return result
    return _ResultFile(path)


def _load_result(path: str) -> Any:
    """In the caller, as the pool's manager thread unpickles a ``_ResultFile``: the result, file removed. A
    file that cannot be read raises there, which the pool reports as BrokenProcessPool."""
    try:
        with open(path, "rb") as f:
            return pickle.load(f)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)


def discard_if_broken(pool: ProcessPoolExecutor) -> None:
    """Forget ``pool`` when a worker died under it (killed, out of memory): the next call starts a new one."""
    global _pool
    probe = None
    with shielded(), contextlib.suppress(BrokenProcessPool, RuntimeError):  # RuntimeError: shut down already
        probe = pool.submit(int)
    if probe is not None:
        probe.cancel()
        return
    with _lock:
        if _pool is pool:
            _pool = None


def shutdown_pool() -> None:
    """Stop the warm pool now (tests; a station at its end). The next capture starts a new one."""
    global _pool
    with _lock:
        pool, _pool = _pool, None
    if pool is not None:
        pool.shutdown(wait=True, cancel_futures=True)


def warm(workers: int) -> None:
    """Start the pool's ``workers`` processes now and wait until each has run (a station's start-up), so
    the first capture forks nothing."""
    pool = process_pool(workers)
    with shielded():
        futures = [submit(pool, _ready) for _ in range(workers)]
    for future in futures:
        future.result()


def is_warm(workers: int) -> bool:
    """True when a pool of ``workers`` processes is running: detection on it costs no start-up."""
    with _lock:
        return _pool is not None and _pool_workers == workers


def _ready() -> int:
    return 1
