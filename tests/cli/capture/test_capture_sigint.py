"""A real Ctrl-C (SIGINT to the whole process group, as a terminal sends it) while worker processes detect:
calibctl exits 130 with its one line, no worker prints a traceback, nothing is stored."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rendered(tmp_path_factory, "good")


def group_pids(pgid: int) -> set[int]:
    pids = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid:  # field 5 of /proc/PID/stat: the process group
            pids.add(int(stat.parent.name))
    return pids


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process group from /proc (Linux)")
def test_sigint_to_the_process_group_during_parallel_detection_stores_nothing(
    sqlite_url: str, good: Path, tmp_path: Path
) -> None:
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    folder = tmp_path / "many"
    folder.mkdir()
    views = sorted(good.glob("*.png"))
    for i in range(800):  # far more than the workers finish before the signal
        shutil.copy(views[i % len(views)], folder / f"img-{i:03d}.png")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "calibctl",
            "--db",
            sqlite_url,
            "capture",
            "--serial",
            "CAM-1",
            "--board",
            "A17",
            "--source",
            str(folder),
            "--jobs",
            "2",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        # calibctl, the resource tracker, the fork server and both workers: detection is running, and the fork
        # server's start, whose few milliseconds ignore SIGINT (worker_pool._started_ignoring_sigint), is over
        while len(group_pids(proc.pid)) < 5 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        # and half a second more, so detection is under way: the signal once failed to stop a capture (exit 0,
        # at load 2 and at load 10) when sent the moment the fifth process appeared; the window it fell in is
        # not known
        time.sleep(0.5)
        assert proc.poll() is None, proc.communicate()
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Interrupted; nothing half-written was kept." in err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    with Store.open(sqlite_url) as store:
        assert store.list_sessions() == [] and store.counts()["images"] == 0
