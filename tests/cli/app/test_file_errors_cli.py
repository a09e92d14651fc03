"""No traceback on a file-system problem: exit 2 and one line naming the path, for every output calibctl
writes.

The suite runs as root, where permissions and read-only folders do not stop a write, so those failures
are injected where the operating system would raise them (``tempfile.mkstemp`` in the target folder,
the write itself, a folder listing), with the errno the kernel gives.
"""

from __future__ import annotations

import errno
import os
import stat
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

import calibctl.files
from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board

REPO = Path(__file__).resolve().parents[3]
runner = CliRunner()


def cli(*args: str):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(result, *parts: str) -> None:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = result.stderr.splitlines()
    assert lines[0].startswith("Error: ") and all(p in lines[0] for p in parts), result.stderr
    assert len(lines) == 2 and lines[1].startswith("Hint: ")


@pytest.fixture
def store_url(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_artifact(calibration(), activate=True, actor="qa", station="st1", reason="solved")
    return sqlite_url


def fail_in(monkeypatch, folder: Path, code: int) -> None:
    """``mkstemp`` in ``folder`` fails the way the kernel refuses a new file there."""
    real = calibctl.files.tempfile.mkstemp

    def mkstemp(*args, **kwargs):
        if Path(kwargs.get("dir", "")) == folder:
            raise OSError(code, os.strerror(code), str(folder))
        return real(*args, **kwargs)

    monkeypatch.setattr(calibctl.files.tempfile, "mkstemp", mkstemp)


def test_export_onto_a_folder_with_force_is_exit_2(store_url, tmp_path):
    folder = tmp_path / "robot"
    folder.mkdir()
    result = cli("--db", store_url, "export", "CAM-0001", "-o", folder, "--force")
    one_line_error(result, f"cannot write {folder}", "it is a folder")


@pytest.mark.parametrize(
    ("code", "words"), [(errno.EROFS, "read-only file system"), (errno.EACCES, "permission denied")]
)
def test_export_into_a_read_only_or_forbidden_folder_is_exit_2(store_url, tmp_path, monkeypatch, code, words):
    fail_in(monkeypatch, tmp_path, code)
    result = cli("--db", store_url, "export", "CAM-0001", "-o", tmp_path / "cam.json")
    one_line_error(result, f"cannot write {tmp_path / 'cam.json'}", words)


def test_disk_full_keeps_the_old_file_and_leaves_no_temporary(store_url, tmp_path, monkeypatch):
    out = tmp_path / "cam.json"
    out.write_text("old\n")

    class Full:
        def __init__(self, fd, mode):
            os.close(fd)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(calibctl.files.os, "fdopen", Full)
    result = cli("--db", store_url, "export", "CAM-0001", "-o", out, "--force")
    one_line_error(result, f"cannot write {out}", "no space left on the device")
    assert out.read_text() == "old\n" and [p.name for p in tmp_path.iterdir()] == sorted(
        p.name for p in tmp_path.iterdir() if not p.name.startswith(".cam.json.")
    )


def test_exports_honour_the_umask_and_force_keeps_the_mode(store_url, tmp_path):
    old = os.umask(0o027)
    try:
        new = tmp_path / "new.yaml"
        assert cli("--db", store_url, "export", "CAM-0001", "-f", "ros", "-o", new).exit_code == 0
        assert stat.S_IMODE(new.stat().st_mode) == 0o640
        os.umask(0o022)
        shared = tmp_path / "shared.yaml"
        assert cli("--db", store_url, "export", "CAM-0001", "-f", "ros", "-o", shared).exit_code == 0
        assert stat.S_IMODE(shared.stat().st_mode) == 0o644
        shared.chmod(0o664)
        assert (
            cli("--db", store_url, "export", "CAM-0001", "-f", "ros", "-o", shared, "--force").exit_code == 0
        )
        assert stat.S_IMODE(shared.stat().st_mode) == 0o664
    finally:
        os.umask(old)


def test_an_unreadable_source_folder_is_exit_2(sqlite_url, tmp_path, monkeypatch):
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board())
    shots = tmp_path / "shots"
    shots.mkdir()
    real = Path.iterdir

    def iterdir(self):
        if self == shots:
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        return real(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)
    result = cli("--db", sqlite_url, "capture", "--serial", "CAM-1", "--board", "A17", "--source", shots)
    one_line_error(result, f"cannot read the source folder {shots}", "permission denied")


def test_plots_into_a_read_only_folder_are_exit_2(tmp_path, monkeypatch):
    logs = tmp_path / "logs"
    logs.mkdir()
    assert cli("synth-residuals", logs / "k1.csv", "--fault", "k1", "--keyframes", "60").exit_code == 0
    plots = tmp_path / "plots"
    plots.mkdir()
    fail_in(monkeypatch, plots, errno.EROFS)
    result = cli("triage", logs / "k1.csv", "--plot", plots)
    one_line_error(result, f"cannot write {plots}", "read-only file system")


@pytest.mark.parametrize("command", ["synth", "synth-residuals"])
def test_synth_into_a_read_only_folder_is_exit_2(tmp_path, monkeypatch, command):
    out = tmp_path / "out"
    out.mkdir()
    fail_in(monkeypatch, out, errno.EROFS)
    args = (
        (out, "--views", "2", "--size", "320x240")
        if command == "synth"
        else (out / "k1.csv", "--fault", "k1")
    )
    one_line_error(cli(command, *args), f"cannot write {out}", "read-only file system")


def test_a_folder_that_cannot_be_created_is_exit_2(tmp_path, monkeypatch):
    real = Path.mkdir

    def mkdir(self, *args, **kwargs):
        if self.parent == tmp_path:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", mkdir)
    one_line_error(
        cli("synth", tmp_path / "new", "--views", "1"), f"cannot create {tmp_path / 'new'}", "read-only"
    )


def test_an_unreadable_lint_input_is_exit_2(tmp_path, monkeypatch):
    path = tmp_path / "cam.yaml"
    path.write_text("x: 1\n")
    real = os.open

    def open_(
        target, *args, **kwargs
    ):  # the bounded reader opens the file itself (calibctl.files.open_regular)
        if Path(target) == path:
            raise PermissionError(errno.EACCES, "Permission denied", str(target))
        return real(target, *args, **kwargs)

    monkeypatch.setattr(os, "open", open_)
    one_line_error(cli("lint", path), f"cannot read {path}", "permission denied")


def test_any_file_system_error_elsewhere_is_one_line_but_a_bug_keeps_its_traceback(store_url, monkeypatch):
    from calibctl.workflows.store_admin import records

    def denied(*_args, **_kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", "/var/lib/calibctl/images")

    monkeypatch.setattr(records, "show", denied)
    one_line_error(
        cli("--db", store_url, "show", "CAM-0001"),
        "cannot access /var/lib/calibctl/images",
        "permission denied",
    )

    def bug(*_args, **_kwargs):
        raise OSError("an OSError without errno is calibctl's own mistake")

    monkeypatch.setattr(records, "show", bug)
    result = cli("--db", store_url, "show", "CAM-0001")
    assert result.exit_code == 2 and "Traceback" in result.stderr


def test_plus_minus_under_an_ascii_locale_is_spelled_out(sqlite_url, tmp_path):
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board())
    env = {**os.environ, "PYTHONIOENCODING": "ascii", "LC_ALL": "C", "PYTHONPATH": str(REPO)}
    env = {k: v for k, v in env.items() if not k.startswith("CALIBCTL_")}
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            "from calibctl.cli.main import run; run()",
            "--db",
            sqlite_url,
            "board",
            "show",
            "A17",
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert "25.030 mm +/- 0.020 mm (1sigma)" in done.stdout


def test_an_input_that_is_not_utf8_is_exit_2(tmp_path):
    path = tmp_path / "cam.yaml"
    path.write_bytes("camera_name: caméra\n".encode("latin-1"))
    one_line_error(cli("lint", path), f"cannot read {path}", "it is not UTF-8 text")


@pytest.mark.parametrize(
    ("code", "words"), [(errno.ENOSPC, "no space left on the device"), (errno.EACCES, "permission denied")]
)
def test_an_image_store_that_cannot_be_written_is_exit_2_and_stores_no_session(
    sqlite_url, tmp_path_factory, monkeypatch, code, words
):
    """The images are stored beside the capture gates (workflows.camera.image_writes): a full disk or an image
    folder the process may not write is still one line, exit 2, and no session."""
    from calibctl.store import images
    from tests.workflows.synth_folders import rendered

    good = rendered(tmp_path_factory, "good")
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board())

    def refused(path, data):
        raise OSError(code, os.strerror(code), str(path.parent))

    monkeypatch.setattr(images, "_link_anonymous", refused)
    result = cli("--db", sqlite_url, "capture", "--serial", "CAM-1", "--board", "A17", "--source", good)
    progress, _, rest = result.stderr.partition("\n")  # the capture's first line says what it examines
    assert progress.startswith("calibctl capture: examining 12 images")
    one_line_error(
        SimpleNamespace(exit_code=result.exit_code, output=result.output, stderr=rest),
        "cannot write the image",
        words,
    )
    with Store.open(sqlite_url) as store:
        assert store.list_sessions() == [] and store.counts()["images"] == 0
