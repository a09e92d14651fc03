"""Regression tests for what benchmarks/hostile_sweep.py found (issue 26: the 407-case categories re-measured).
Special files are made in tmp_path only (mkfifo), never a system device node."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.files import read_text

runner = CliRunner()


def one_line_error(result, *parts: str) -> None:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = result.stderr.splitlines()
    assert lines[0].startswith("Error: ") and all(p in lines[0] for p in parts), result.stderr
    assert lines[1].startswith("Hint: ")


@pytest.mark.parametrize("command", [["import"], ["lint"], ["--station-config"]])
def test_a_fifo_given_as_an_input_file_is_refused_instead_of_waiting_for_a_writer_forever(tmp_path: Path, command):
    """`import x.json` on a FIFO blocked in open() until the sweep killed it after 120 s."""
    fifo = tmp_path / "x.json"
    os.mkfifo(fifo)
    db = tmp_path / "store.db"
    args = [*command, str(fifo)] if command[0] != "--station-config" else [*command, str(fifo), "history", "CAM"]
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


BOARD_ADD = ["board", "add", "B2", "--kind", "chessboard", "--cols", "9", "--rows", "6", "--square-mm", "25",
             "--uncertainty-mm", "0.02", "--instrument", "calipers", "--measured-by", "qa", "--measured-on", "2026-03-11"]


@pytest.mark.parametrize(("args", "env", "what"), [
    (["triage", "{fifo}"], {}, "cannot read the residual buffer"),
    (["gauge", "{fifo}"], {}, "cannot read the odometry log"),
    (["handeye", "{fifo}", "--from", "base", "--to", "cam"], {}, "cannot read the motions CSV"),
    (["timeoffset", "{fifo}", "{fifo}"], {}, "cannot read the gyro log"),
    (["keys", "export-public", "--key", "{fifo}"], {}, "cannot read the signing key"),
    ([*BOARD_ADD, "--evidence", "{fifo}"], {}, "cannot read the evidence file"),
    (BOARD_ADD, {"CALIBCTL_SIGNING_KEY": "{fifo}"}, "cannot read the signing key"),
], ids=["triage", "gauge", "handeye", "timeoffset", "keys export-public", "board evidence", "signing key"])
def test_every_reader_refuses_a_fifo_with_one_line_and_stores_nothing(tmp_path: Path, args, env, what):
    """Each of these waited forever in open() on a FIFO (no writer ever comes)."""
    fifo = tmp_path / "t"
    os.mkfifo(fifo)
    db = tmp_path / "store.db"
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", *[a.replace("{fifo}", str(fifo)) for a in args]],
                           env={k: v.replace("{fifo}", str(fifo)) for k, v in env.items()})
    one_line_error(result, what, "it is a FIFO (named pipe), not a regular file")
    assert not db.exists()
