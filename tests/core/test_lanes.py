"""core.lanes: a map over the caller and a pool that keeps the sequential loop's order, results and first
error,
and never deadlocks a bounded pool on nested work."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import pytest

from calibctl.core.lanes import Lanes, lanes_map


def test_without_a_pool_it_is_the_sequential_loop_on_the_calling_thread() -> None:
    seen: list[tuple[int, str]] = []
    out = Lanes().map(lambda i: seen.append((i, threading.current_thread().name)) or i * i, [3, 1, 2])
    assert out == [9, 1, 4]
    assert seen == [
        (3, threading.current_thread().name),
        (1, threading.current_thread().name),
        (2, threading.current_thread().name),
    ]
    assert lanes_map(None, str, [1, 2]) == ["1", "2"]


@pytest.mark.parametrize("workers", [1, 3])
def test_results_come_in_input_order_whoever_computed_them(workers) -> None:
    names: set[str] = set()
    release = threading.Event()

    def work(i: int) -> int:
        names.add(threading.current_thread().name)
        if i == 0:
            release.wait(5)  # the caller holds item 0 until a worker has taken another item
        else:
            release.set()
        return 10 * i

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="lane") as pool:
        assert Lanes(pool).map(work, list(range(8))) == [10 * i for i in range(8)]
    assert threading.current_thread().name in names and any(n.startswith("lane") for n in names)


def test_nested_maps_on_a_one_worker_pool_finish() -> None:
    """Three levels deep on jobs 2: every waiting lane runs the work no worker has started itself."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        lanes = Lanes(pool)
        inner = lambda i: sum(lanes.map(lambda j: i * j, [1, 2, 3]))  # noqa: E731
        middle = lambda i: lanes.map(inner, [i, i + 1])  # noqa: E731
        background = lanes.start(lambda: lanes.map(middle, [1, 2]))
        assert lanes.map(middle, [5, 6]) == [[30, 36], [36, 42]]
        assert background.result() == [[6, 12], [12, 18]]


def test_the_first_error_in_input_order_is_raised_and_the_items_after_it_never_run() -> None:
    finished: list[int] = []

    def work(i: int) -> int:
        if i in (2, 4):
            raise ValueError(f"item {i}")
        finished.append(i)
        return i

    with ThreadPoolExecutor(max_workers=1) as pool:
        gate = threading.Event()
        blocker = pool.submit(gate.wait, 5)  # the only worker is busy: every item waits in the queue
        with pytest.raises(ValueError, match="item 2"):
            Lanes(pool).map(work, list(range(30)))
        gate.set()
        blocker.result()
    assert finished == [0, 1]  # the caller ran 0, 1, 2 itself; 3.. were cancelled when 2 failed


def test_an_error_waits_for_the_items_already_running() -> None:
    finished: list[int] = []

    def work(i: int) -> int:
        if i == 0:
            raise ValueError("item 0")
        threading.Event().wait(0.05)
        finished.append(i)
        return i

    with ThreadPoolExecutor(max_workers=3) as pool:
        with pytest.raises(ValueError, match="item 0"):
            Lanes(pool).map(work, [0, 1, 2, 3, 4, 5])
        done_when_raised = list(finished)
    assert finished == done_when_raised  # what had started had finished when the error reached the caller


def test_a_started_result_is_computed_by_the_caller_when_no_worker_took_it() -> None:
    with ThreadPoolExecutor(max_workers=1) as pool:
        gate = threading.Event()
        busy = pool.submit(gate.wait, 5)  # the only worker is busy
        deferred = Lanes(pool).start(lambda: threading.current_thread().name)
        assert deferred.result() == threading.current_thread().name
        gate.set()
        busy.result()
        skipped = Lanes(pool).start(lambda: 1 / 0)
        skipped.settle()  # cancelled or finished; its error is not raised here


def test_one_thread_blas_blocks_on_lanes_keep_the_limit_of_the_block_around_the_pool() -> None:
    """The pool's owner opens a block around the pool; the lanes open and close theirs inside it, in any
    order:
    BLAS stays on one thread until the owner's block closes, then gets its threads back."""
    import cv2  # noqa: F401  (its bundled OpenBLAS is one of the libraries limited)
    from threadpoolctl import threadpool_info, threadpool_limits

    from calibctl.core.blas_threads import single_threaded_blas

    def counts() -> list[int]:
        return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]

    with threadpool_limits(limits=2):
        before = counts()
        # at least one library takes the limit (one built single-threaded stays at 1: OpenCV 4.10's wheel)
        assert 2 in before
        seen: list[list[int]] = []
        with single_threaded_blas():
            inner_open, inner_closed = threading.Event(), threading.Event()

            def lane() -> None:
                with single_threaded_blas():
                    inner_open.set()
                inner_closed.set()

            worker = threading.Thread(target=lane)
            worker.start()
            with single_threaded_blas():
                inner_open.wait(5)
                inner_closed.wait(5)
                seen.append(counts())  # a lane's block has closed; the others still hold the limit
            worker.join()
            seen.append(counts())
        assert seen == [[1] * len(before)] * 2
        assert counts() == before
