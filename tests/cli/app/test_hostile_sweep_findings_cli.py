"""Regression tests for what benchmarks/hostile_sweep.py found (its 407-case categories re-measured).
Special files are made in tmp_path only (mkfifo), never a system device node."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.files import read_text
from tests.artifacts.factories import measured_board_args

runner = CliRunner()


def one_line_error(result, *parts: str) -> None:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = result.stderr.splitlines()
    assert lines[0].startswith("Error: ") and all(p in lines[0] for p in parts), result.stderr
    assert lines[1].startswith("Hint: ")


@pytest.mark.parametrize("command", [["import"], ["lint"], ["--station-config"]])
def test_a_fifo_given_as_an_input_file_is_refused_instead_of_waiting_for_a_writer_forever(
    tmp_path: Path, command
):
    """`import x.json` on a FIFO blocked in open() until the sweep killed it after 120 s."""
    fifo = tmp_path / "x.json"
    os.mkfifo(fifo)
    db = tmp_path / "store.db"
    args = (
        [*command, str(fifo)] if command[0] != "--station-config" else [*command, str(fifo), "history", "CAM"]
    )
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", *args])
    one_line_error(result, str(fifo), "it is a FIFO (named pipe), not a regular file")
    assert not db.exists()  # nothing stored, no store created


def test_read_text_refuses_a_fifo_and_still_reads_a_regular_file(tmp_path: Path):
    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    with pytest.raises(Exception, match="it is a FIFO"):
        read_text(fifo)
    with pytest.raises(Exception, match="it is a FIFO"):
        read_text(fifo, max_bytes=10)
    (tmp_path / "r.txt").write_text("ok\n")
    assert read_text(tmp_path / "r.txt") == "ok\n" and read_text(tmp_path / "r.txt", max_bytes=10) == "ok\n"


BOARD_ADD = measured_board_args("B2")


@pytest.mark.parametrize(
    ("args", "env", "what"),
    [
        (["triage", "{fifo}"], {}, "cannot read the residual buffer"),
        (["gauge", "{fifo}"], {}, "cannot read the odometry log"),
        (["handeye", "{fifo}", "--from", "base", "--to", "cam"], {}, "cannot read the motions CSV"),
        (["timeoffset", "{fifo}", "{fifo}"], {}, "cannot read the gyro log"),
        (["keys", "export-public", "--key", "{fifo}"], {}, "cannot read the signing key"),
        ([*BOARD_ADD, "--evidence", "{fifo}"], {}, "cannot read the evidence file"),
        (BOARD_ADD, {"CALIBCTL_SIGNING_KEY": "{fifo}"}, "cannot read the signing key"),
    ],
    ids=["triage", "gauge", "handeye", "timeoffset", "keys export-public", "board evidence", "signing key"],
)
def test_every_reader_refuses_a_fifo_with_one_line_and_stores_nothing(tmp_path: Path, args, env, what):
    """Each of these waited forever in open() on a FIFO (no writer ever comes)."""
    fifo = tmp_path / "t"
    os.mkfifo(fifo)
    db = tmp_path / "store.db"
    result = runner.invoke(
        app,
        ["--db", f"sqlite:///{db}", *[a.replace("{fifo}", str(fifo)) for a in args]],
        env={k: v.replace("{fifo}", str(fifo)) for k, v in env.items()},
    )
    one_line_error(result, what, "it is a FIFO (named pipe), not a regular file")
    assert not db.exists()


@pytest.mark.parametrize(
    ("args", "what"),
    [
        (["fleet", "ingest", "{fifo}"], "cannot ingest"),
        (
            ["station", "--board", "A17", "--source-template", "{dir}/{serial}", "--serials", "{fifo}"],
            "cannot read the serials file",
        ),
    ],
    ids=["fleet ingest", "station --serials"],
)
def test_store_commands_refuse_a_fifo_input_and_store_nothing(tmp_path: Path, args, what):
    from calibctl.store.repository import Store
    from tests.artifacts.factories import measured_board

    url = f"sqlite:///{tmp_path / 'store.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17"))
    fifo = tmp_path / "t"
    os.mkfifo(fifo)
    argv = [a.replace("{fifo}", str(fifo)).replace("{dir}", str(tmp_path)) for a in args]
    result = runner.invoke(app, ["--db", url, *argv])
    one_line_error(result, what, "it is a FIFO (named pipe), not a regular file")
    with Store.open(url) as store:
        assert store.serials() == [] and store.verify().problems == []


def test_ctrl_c_while_calibctl_starts_is_one_line_and_exit_130():
    """SIGINT during start-up (imports, parsing) ended in a KeyboardInterrupt traceback (sweep: `solve`
    interrupted at 0.3 s and 0.8 s). The signal is sent once the CLI package is imported, not after a
    delay."""
    import signal
    import subprocess
    import sys

    code = (
        "import os, signal, calibctl.cli.main; os.kill(os.getpid(), signal.SIGINT); import time; "
        "time.sleep(30)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # noqa: PLW1509
    assert done.returncode == 130 and done.stderr == "Interrupted before anything was done.\n"


def test_a_running_command_gets_ctrl_c_as_keyboard_interrupt_again(tmp_path: Path):
    import signal

    from calibctl.cli import startup_interrupt

    previous = signal.signal(signal.SIGINT, startup_interrupt)
    try:
        runner.invoke(app, ["--db", f"sqlite:///{tmp_path / 's.db'}", "history", "CAM"])
        assert (
            signal.getsignal(signal.SIGINT) is signal.default_int_handler
        )  # the commands' cleanup relies on it
    finally:
        signal.signal(signal.SIGINT, previous)
