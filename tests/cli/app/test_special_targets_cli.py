"""`--force` replaces only regular files: every writer refuses a symlink, FIFO, folder or device node at its
output path with exit 2 and one line, and leaves that thing exactly as it was (docs/hardening.md).

Special files are made in tmp_path only (mkfifo, symlink, mkdir; mknod where the kernel permits it),
never a system device node.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.test_files import SPECIAL_KINDS, _special

RUNNER = CliRunner()


def cli(*args: object):
    return RUNNER.invoke(app, [str(a) for a in args], terminal_width=200)


@pytest.fixture
def store_url(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_artifact(calibration(), activate=True, actor="qa", station="st1", reason="solved")
    return sqlite_url


def _motions(tmp_path: Path) -> Path:
    log = tmp_path / "motions.csv"
    assert cli("synth-motions", log, "--seed", "1").exit_code == 0
    return log


# writer name -> (command line for a given target path, in a test's tmp_path and store)
WRITERS: dict[str, Callable[[Path, Path, str], list[object]]] = {
    "export": lambda out, tmp, db: ["--db", db, "export", "CAM-0001", "-o", out, "--force"],
    "export ros": lambda out, tmp, db: ["--db", db, "export", "CAM-0001", "-f", "ros", "-o", out, "--force"],
    "report": lambda out, tmp, db: ["--db", db, "report", "CAM-0001", "-o", out, "--force"],
    "handeye -o": lambda out, tmp, db: [
        "handeye",
        _motions(tmp),
        "--from",
        "lidar",
        "--to",
        "camera",
        "-o",
        out,
        "--force",
    ],
    "handeye --tf-static": lambda out, tmp, db: [
        "handeye",
        _motions(tmp),
        "--from",
        "lidar",
        "--to",
        "camera",
        "--tf-static",
        out,
        "--force",
    ],
    "synth-motions": lambda out, tmp, db: ["synth-motions", out, "--seed", "1", "--force"],
    "synth-residuals": lambda out, tmp, db: [
        "synth-residuals",
        out,
        "--fault",
        "focal",
        "--keyframes",
        "5",
        "--force",
    ],
    "keys init": lambda out, tmp, db: ["keys", "init", "--key", out, "--force"],
    "keys export-public": lambda out, tmp, db: (
        cli("keys", "init", "--key", tmp / "k.pem")
        and ["keys", "export-public", "--key", tmp / "k.pem", "-o", out, "--force"]
    ),
}


@pytest.mark.parametrize("kind", ["symlink", "fifo", "folder", "device"])
@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_every_writer_refuses_a_special_file_at_its_output(store_url, tmp_path, writer, kind):
    target = tmp_path / "target.out"
    _special(kind, target, tmp_path)
    before = os.lstat(target)
    result = cli(*WRITERS[writer](target, tmp_path, store_url))
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert f"cannot write {target}: it is " in result.stderr.replace("the signing key ", "")
    after = os.lstat(target)
    assert (after.st_mode, after.st_ino, after.st_rdev) == (before.st_mode, before.st_ino, before.st_rdev)
    if kind == "symlink":
        assert (tmp_path / "victim.txt").read_text() == "not ours\n"


def test_synth_refuses_a_symlink_among_its_views(tmp_path):
    out = tmp_path / "views"
    assert cli("synth", out, "--views", "4", "--seed", "3").exit_code == 0
    victim = tmp_path / "victim.txt"
    victim.write_text("not ours\n")
    first = sorted(out.glob("view-*.png"))[0]
    first.unlink()
    os.symlink(victim, first)
    (out / "truth.json").unlink()
    os.mkfifo(out / "truth.json")
    result = cli("synth", out, "--views", "4", "--seed", "3", "--force")
    assert result.exit_code == 2 and "not a regular file" in result.stderr, result.output
    assert victim.read_text() == "not ours\n"
    assert stat.S_ISLNK(os.lstat(first).st_mode)


def test_a_regular_file_is_still_replaced_with_force_and_keeps_its_mode(store_url, tmp_path):
    out = tmp_path / "cam.json"
    out.write_text("old\n")
    out.chmod(0o640)
    assert cli("--db", store_url, "export", "CAM-0001", "-o", out, "--force").exit_code == 0
    assert out.read_text() != "old\n" and stat.S_IMODE(out.stat().st_mode) == 0o640


def test_special_kinds_are_the_ones_the_writer_knows():
    assert set(SPECIAL_KINDS) >= {"symlink", "fifo", "folder", "device"}


def test_triage_plots_never_replace_a_symlink(tmp_path):
    pytest.importorskip("matplotlib", reason="the plots extra is not installed")
    csv = tmp_path / "in.csv"
    assert (
        cli("synth-residuals", csv, "--fault", "rotation", "--seed", "2", "--keyframes", "60").exit_code == 0
    )
    plots = tmp_path / "plots"
    assert cli("triage", csv, "--plot", plots).exit_code in (0, 1)
    first = sorted(plots.glob("*.png"))[0]
    victim = tmp_path / "victim.txt"
    victim.write_text("not ours\n")
    first.unlink()
    os.symlink(victim, first)
    result = cli("triage", csv, "--plot", plots)
    assert result.exit_code == 2 and "it is a symbolic link, not a regular file" in result.stderr, (
        result.output
    )
    assert victim.read_text() == "not ours\n" and first.is_symlink()
