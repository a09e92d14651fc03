"""A read-only SQLite store (file or folder) can be read; a write to it says read-only (docs/hardening.md).

Root ignores file permissions, so the real-permission test runs calibctl with the capabilities that let
root do that (dac_override, dac_read_search, fowner) dropped from its bounding set (``setpriv``); as
any other user plain chmod is enough. An in-process test covers the decision itself.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store import engine as engine_module
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

REPO = Path(__file__).resolve().parents[3]
READS = [
    ("history", "CAM-0001"),
    ("show", "CAM-0001"),
    ("export", "CAM-0001"),
    ("lint", "--serial", "CAM-0001"),
    ("db", "verify"),
]


@pytest.fixture
def store(tmp_path: Path) -> Path:
    folder = tmp_path / "station"
    folder.mkdir()
    with Store.open(f"sqlite:///{folder / 'c.db'}") as opened:
        opened.add_artifact(calibration(), activate=True, actor="qa", station="st1", reason="solved")
    return folder / "c.db"


def _unprivileged(args: list[str]) -> subprocess.CompletedProcess:
    prefix: list[str] = []
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("running as root without setpriv: cannot drop the override of file permissions")
        prefix = [setpriv, "--bounding-set=-dac_override,-dac_read_search,-fowner", "--"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [*prefix, sys.executable, "-m", "calibctl", *args],
        capture_output=True,
        text=True,
        env=env,
        check=False,
        timeout=300,
    )


@pytest.mark.parametrize("what", ["file", "folder"])
def test_read_commands_work_on_a_read_only_store_and_a_write_says_read_only(store, what):
    target = store if what == "file" else store.parent
    before = store.read_bytes()
    target.chmod(0o444 if what == "file" else 0o555)
    try:
        url = f"sqlite:///{store}"
        for args in READS:
            done = _unprivileged(["--db", url, *args])
            assert done.returncode == 0, (args, done.stderr)
        done = _unprivileged(["--db", url, "rollback", "CAM-0001", "--to", "1", "--reason", "x"])
        assert done.returncode == 2, done.stderr
        assert (
            "is read-only for this user; nothing was written" in done.stderr
            and "Traceback" not in done.stderr
        )
    finally:
        target.chmod(0o755 if what == "folder" else 0o644)
    assert store.read_bytes() == before  # (SQLite may leave its own -wal/-shm beside a read-only file)


def test_a_store_this_user_cannot_write_is_opened_read_only(store, monkeypatch):
    real = os.access
    monkeypatch.setattr(
        engine_module.os, "access", lambda p, mode: False if mode == os.W_OK else real(p, mode)
    )
    assert engine_module.read_only_file(store)
    runner = CliRunner()
    url = f"sqlite:///{store}"
    shown = runner.invoke(app, ["--db", url, "show", "CAM-0001"])
    assert shown.exit_code == 0, shown.output
    done = runner.invoke(app, ["--db", url, "rollback", "CAM-0001", "--to", "1", "--reason", "x"])
    assert done.exit_code == 2 and "read-only for this user" in done.stderr
    assert not engine_module.read_only_file(store.parent / "absent.db")  # a new store is created as before
