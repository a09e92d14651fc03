"""`calibctl export X | head -1`: a reader that goes away ends calibctl quietly with 141, never a traceback.

The read end of the pipe is closed before calibctl starts, so its first write fails whatever the size
of the output (with ``head`` that only happens once the output outgrows the pipe's buffer).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from calibctl.cli.streams import EXIT_CLOSED_PIPE
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def stored(tmp_path_factory) -> str:
    url = f"sqlite:///{tmp_path_factory.mktemp('pipe') / 'store.db'}"
    with Store.open(url) as store:
        store.add_artifact(
            calibration(serial="CAM-0001"), activate=True, actor="qa", station="st1", reason="solved"
        )
    return url


def _into_closed_pipe(*args: str) -> subprocess.CompletedProcess[str]:
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        return subprocess.run(
            [sys.executable, "-m", "calibctl", *args],
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            check=False,
        )
    finally:
        os.close(write_end)


@pytest.mark.parametrize(
    "args",
    [
        ["export", "CAM-0001"],  # print() of a JSON document
        ["export", "CAM-0001", "--format", "ros"],
        ["history", "CAM-0001"],  # a rich table
        ["history", "CAM-0001", "--json"],
        ["board", "list"],
        ["--help"],  # written while parsing, before any command runs
        ["export", "--help"],
    ],
)
def test_a_closed_stdout_ends_with_141_and_nothing_on_stderr(stored: str, args: list[str]) -> None:
    done = _into_closed_pipe("--db", stored, *args)
    assert done.returncode == EXIT_CLOSED_PIPE == 141
    assert done.stderr == ""


def test_with_an_open_pipe_the_same_command_exits_0(stored: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "calibctl", "--db", stored, "export", "CAM-0001"],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        check=False,
    )
    assert done.returncode == 0 and done.stdout.startswith("{") and done.stderr == ""
