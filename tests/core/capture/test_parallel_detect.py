"""Detection on N workers gives the outcomes of one: same status, reason and hash, bit-identical corners,
at jobs 1, 2 and 4, on threads and on the warm process pool (a few files a task), on renders and on real
photos; Ctrl-C cancels the queued files and leaves the pool usable; a worker killed mid-task names every file
of its task; each worker runs OpenCV and BLAS on one thread."""

from __future__ import annotations

import os
import shutil
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibctl.core.blas_threads import available_cores, thread_counts
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import worker_pool
from calibctl.core.capture.image_outcomes import (
    CHUNK_MAX_FILES,
    PROCESS_MIN_FILES,
    ImageOutcome,
    choose_executor,
    classify_files,
    classify_session,
    list_images,
    task_chunks,
)
from calibctl.core.synth.pinhole import Photometry, PinholeCamera, render_view
from calibctl.core.synth.scenes import scenario_poses
from tests.datasets import LEFT_RIGHT, needs_datasets

BOARD = BoardSpec.chessboard(9, 6, 0.025)
CAMERA = PinholeCamera.seed_reference()
JOBS = (1, 2, 4)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """10 renders plus the outcomes that are not 'accepted': a copy, a blurred view, an empty scene, a
    broken file, a wrong-size view."""
    folder = tmp_path_factory.mktemp("rendered")
    rng = np.random.default_rng(24)
    poses = scenario_poses("good", CAMERA, BOARD, 11, rng)
    for i, T in enumerate(poses[:10]):
        assert cv2.imwrite(
            str(folder / f"v{i:02d}.png"), render_view(CAMERA, BOARD, T, rng, Photometry.random(rng))
        )
    shutil.copy(folder / "v00.png", folder / "w-copy.png")
    blurred = render_view(CAMERA, BOARD, poses[10], rng, Photometry(blur_sigma_px=4.5))
    assert cv2.imwrite(str(folder / "x-blurred.png"), blurred)
    assert cv2.imwrite(str(folder / "y-empty.png"), (rng.uniform(0, 1, (480, 640)) * 255).astype(np.uint8))
    assert cv2.imwrite(str(folder / "y-big.png"), cv2.resize(cv2.imread(str(folder / "v01.png")), (800, 600)))
    (folder / "z-broken.png").write_bytes(b"not a png")
    return list_images(folder)


@pytest.fixture(scope="module")
def tripled(rendered: list[Path], tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """The rendered set three times over (a-, b-, c- copies): 45 files, not a multiple of any task size, with
    z-broken.png (index 14) and y-big.png (index 12) inside the second 2-worker task, not at its start."""
    folder = tmp_path_factory.mktemp("tripled")
    for prefix in "abc":
        for path in rendered:
            shutil.copy(path, folder / f"{prefix}-{path.name}")
    paths = list_images(folder)
    second = task_chunks(range(len(paths)), 2)[1]
    assert len(paths) == 45 and second[0] < 12 < 14 <= second[-1]  # what the tests below rely on
    return paths


def assert_same(runs: dict[str, list[ImageOutcome]]) -> None:
    (first_name, first), *others = runs.items()
    for name, outcomes in others:
        assert [o.name for o in outcomes] == [o.name for o in first], name
        for a, b in zip(outcomes, first, strict=True):
            assert (a.status, a.reason, a.sha256, a.image_size, a.method, a.edge_width_px) == (
                b.status,
                b.reason,
                b.sha256,
                b.image_size,
                b.method,
                b.edge_width_px,
            ), f"{name} vs {first_name}: {a.name}"
            if b.corners_px is None:
                assert a.corners_px is None
            else:
                assert a.corners_px is not None and a.corners_px.tobytes() == b.corners_px.tobytes()
                assert a.corner_ids is not None and a.corner_ids.tobytes() == b.corner_ids.tobytes()  # type: ignore[union-attr]


def runs_at_every_job_count(paths: list[Path]) -> dict[str, list[ImageOutcome]]:
    runs = {}
    for jobs in JOBS:
        for executor in ("thread", "process"):
            runs[f"{executor} x{jobs}"] = classify_session(paths, BOARD, workers=jobs, executor=executor)
    return runs


def test_renders_get_the_same_outcomes_and_bit_identical_corners_at_jobs_1_2_and_4(
    rendered: list[Path],
) -> None:
    runs = runs_at_every_job_count(rendered)
    assert_same(runs)
    statuses = {o.name: o.status for o in runs["thread x1"]}
    assert statuses["w-copy.png"] == "near_duplicate" and statuses["x-blurred.png"] == "blurred"
    assert statuses["y-empty.png"] == "no_board" and statuses["y-big.png"] == "wrong_size"
    assert statuses["z-broken.png"] == "unreadable"
    assert sum(s == "accepted" for s in statuses.values()) == 10


@needs_datasets
def test_real_photos_get_the_same_outcomes_at_jobs_1_2_and_4() -> None:
    paths = list_images(LEFT_RIGHT)
    runs = runs_at_every_job_count(paths)
    assert_same(runs)
    assert sum(o.accepted for o in runs["process x4"]) >= 20  # of 26: the set's boards are found


def test_auto_runs_a_few_files_on_threads_and_many_or_a_warm_pool_on_processes() -> None:
    worker_pool.shutdown_pool()
    assert choose_executor("auto", 4, PROCESS_MIN_FILES) == "process"
    assert choose_executor("auto", 4, PROCESS_MIN_FILES - 1) == "thread"
    worker_pool.warm(2)  # a station's start-up: the pool runs, so a few files go to it too
    assert worker_pool.is_warm(2) and not worker_pool.is_warm(4)
    assert choose_executor("auto", 2, 3) == "process" and choose_executor("auto", 4, 3) == "thread"
    assert choose_executor("auto", 1, 1000) == "thread"  # one worker: no pool at all
    assert choose_executor("thread", 4, 1000) == "thread" and choose_executor("process", 2, 3) == "process"
    with pytest.raises(ValueError, match="executor must be one of auto, thread, process"):
        choose_executor("cluster", 2, 10)


def test_a_worker_process_runs_opencv_and_blas_on_one_thread() -> None:
    pool = worker_pool.process_pool(2)
    counts = pool.submit(thread_counts).result(timeout=120)
    assert counts["opencv"] == 1
    blas = {name: n for name, n in counts.items() if "blas" in name.lower()}
    assert blas and set(blas.values()) == {1}, counts  # numpy's and OpenCV's OpenBLAS


def test_ctrl_c_cancels_the_queued_files_and_leaves_the_warm_pool_usable(rendered: list[Path]) -> None:
    paths = rendered * 4
    seen: list[int] = []

    def interrupt_at_the_third(done: int, total: int, outcome: ImageOutcome) -> None:
        seen.append(done)
        if done == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        classify_files(paths, BOARD, workers=2, executor="process", progress=interrupt_at_the_third)
    assert seen == [1, 2, 3]  # nothing was reported after the interrupt
    assert_same(
        {
            "after": classify_files(rendered, BOARD, workers=2, executor="process"),
            "one": classify_files(rendered, BOARD, workers=1),
        }
    )


def _broken_pool() -> ProcessPoolExecutor:
    """The warm pool of 2 with one worker killed (the stand-in for the out-of-memory killer), once the pool's
    manager thread has noticed."""
    import signal
    import time

    pool = worker_pool.process_pool(2)
    os.kill(pool.submit(os.getpid).result(timeout=120), signal.SIGKILL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # the pool's manager thread notices the death on its own
        try:
            pool.submit(int).result(timeout=60)
        except BrokenProcessPool:
            break
        time.sleep(0.01)
    return pool


def test_a_killed_worker_is_reported_and_the_next_run_gets_a_new_pool(rendered: list[Path]) -> None:
    from calibctl.errors import WorkerDiedError

    pool = _broken_pool()
    with pytest.raises(
        WorkerDiedError,
        match=r"a detection worker process died .* not yet detected: .*nothing was "
        r"stored",
    ) as died:
        classify_files(rendered, BOARD, workers=2, executor="process")
    assert isinstance(died.value.__cause__, BrokenProcessPool) and died.value.exit_code == 2
    assert "free memory" in (died.value.hint or "")
    assert worker_pool.process_pool(2) is not pool  # forgotten: the next run starts a new pool
    outcomes = classify_files(rendered, BOARD, workers=2, executor="process")
    assert sum(o.status == "accepted" for o in outcomes) >= 10


def test_a_file_started_on_a_broken_pool_is_detected_on_a_fresh_one(rendered: list[Path]) -> None:
    """A station watching its folder starts each picture as it lands: a pool a dead worker broke in between is
    replaced, and the picture's outcome is the one a sequential run gives."""
    from calibctl.core.capture.image_outcomes import start_file

    pool = _broken_pool()
    outcome, _ = start_file(rendered[0], BOARD, 2).result(timeout=120)
    assert worker_pool.process_pool(2) is not pool
    assert_same({"fresh pool": [outcome], "one": classify_files(rendered[:1], BOARD, workers=1)})


def test_the_default_job_count_is_the_cores_this_process_may_use() -> None:
    expected = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    assert available_cores() == expected


def test_solve_stages_run_opencv_and_blas_on_one_thread_and_give_the_threads_back() -> None:
    """solve_rig, fit_handeye, the solves and the capture gates enter ``single_threaded``: inside it
    every library runs one thread, outside the counts are what they were."""
    from threadpoolctl import threadpool_limits

    from calibctl.core.blas_threads import single_threaded

    with threadpool_limits(limits=2):
        cv2.setNumThreads(2)
        try:
            before = thread_counts()
            with single_threaded():
                inside = thread_counts()
                with single_threaded():
                    pass
                assert thread_counts() == inside  # a nested block gives nothing back early
            assert set(inside.values()) == {1}
            assert thread_counts() == before and before["opencv"] == 2
        finally:
            cv2.setNumThreads(-1)


@pytest.mark.parametrize(
    ("n", "workers"), [(0, 2), (1, 2), (7, 2), (15, 2), (45, 2), (96, 2), (97, 4), (96, 16), (1000, 1)]
)
def test_task_chunks_cover_every_file_once_in_order_and_shrink_to_single_files(n: int, workers: int) -> None:
    todo = list(range(0, 3 * n, 3))  # any file numbers: those a station detected early are left out
    chunks = task_chunks(todo, workers)
    assert [i for chunk in chunks for i in chunk] == todo
    sizes = [len(chunk) for chunk in chunks]
    assert all(1 <= size <= CHUNK_MAX_FILES for size in sizes)
    assert sizes == sorted(sizes, reverse=True)  # the long tasks first, the single files last
    if n:
        assert sizes[-1] == 1
    if n >= 96 and workers == 2:
        assert len(chunks) <= n // 3  # the point: a few files per round trip to a worker


@pytest.mark.parametrize("jobs", [2, 4])
def test_files_in_tasks_report_in_order_once_each_with_an_unreadable_file_inside_a_task(
    tripled: list[Path], jobs: int
) -> None:
    reported: list[tuple[int, int, str]] = []
    outcomes = classify_files(
        tripled,
        BOARD,
        workers=jobs,
        executor="process",
        progress=lambda done, total, o: reported.append((done, total, o.name)),
    )
    assert [done for done, _, _ in reported] == list(range(1, 46)) and {
        total for _, total, _ in reported
    } == {45}
    assert sorted(name for _, _, name in reported) == [p.name for p in tripled]  # each file once
    assert [o.name for o in outcomes] == [p.name for p in tripled]
    assert outcomes[14].status == "unreadable" and outcomes[13].status == "no_board" and outcomes[15].accepted
    assert_same({f"process x{jobs}": outcomes, "one": classify_files(tripled, BOARD, workers=1)})


def kill_own_worker_at_the_800x600_file(gray: np.ndarray) -> None:
    """A ``summarize`` that kills the detection worker running it (the stand-in for the out-of-memory killer)
    when handed y-big.png, the one 800x600 file."""
    import signal

    if gray.shape == (600, 800):
        os.kill(os.getpid(), signal.SIGKILL)


def test_a_worker_killed_mid_task_names_every_file_of_its_task(tripled: list[Path]) -> None:
    """The worker dies at a-y-big.png, the 5th file of its task: the 4 files it had detected before were never
    reported, so they are named with it, and nothing reported is named."""
    from calibctl.errors import WorkerDiedError

    pool = worker_pool.process_pool(2)
    reported: list[str] = []
    with pytest.raises(WorkerDiedError, match=r"a detection worker process died") as died:
        classify_files(
            tripled,
            BOARD,
            workers=2,
            executor="process",
            summarize=kill_own_worker_at_the_800x600_file,
            progress=lambda done, total, o: reported.append(o.name),
        )
    assert died.value.exit_code == 2 and isinstance(died.value.__cause__, BrokenProcessPool)
    tasks = task_chunks(range(len(tripled)), 2)
    assert not {tripled[i].name for i in tasks[1]} & set(reported)  # the killed task: none of it reported
    named = int(str(died.value).split(" with ")[1].split(" image(s)")[0])
    assert len(tasks[1]) <= named <= len(tripled) - len(reported)
    first = str(died.value).split("not yet detected: ")[1].split(",")[0]
    assert first not in reported and first in {
        tripled[task[0]].name for task in tasks[:2]
    }  # a whole task named
    assert worker_pool.process_pool(2) is not pool  # forgotten: the next run starts a new pool
