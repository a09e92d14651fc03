"""The working folder changes nothing: calibctl run from a folder that holds a ``calibctl/`` package, a
``cv2.py`` and a ``numpy/`` package imports the installed ones, in the command and in every detection worker
(the fork server's ``python -c`` would otherwise put that folder first on its path, and every worker inherits
what it imported). Run as a user runs it: the installed ``calibctl`` script in a fresh process, from the decoy
folder, on 40 images (the process pool's side of ``choose_executor``)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from calibctl.core.capture.image_outcomes import PROCESS_MIN_FILES
from calibctl.store.repository import Store
from calibctl.workflows.synth.synth import run_synth
from tests.artifacts.factories import measured_board

VIEWS = 40
CALIBCTL = Path(sys.executable).parent / "calibctl"


@pytest.fixture(scope="module")
def forty(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("forty") / "CAM-1"
    run_synth(out, "good", seed=3, views=VIEWS)
    (out / "truth.json").unlink()
    assert len(list(out.iterdir())) == VIEWS >= PROCESS_MIN_FILES
    return out


@pytest.fixture
def decoys(tmp_path: Path) -> Path:
    """Importable but wrong: an empty ``calibctl`` and ``numpy`` package, a ``cv2`` module without OpenCV."""
    folder = tmp_path / "work"
    for package in ("calibctl", "numpy"):
        (folder / package).mkdir(parents=True)
        (folder / package / "__init__.py").write_text("DECOY = True\n")
    (folder / "cv2.py").write_text("DECOY = True\n")
    return folder


def _calibctl(cwd: Path, *args: str, stdin: str | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(CALIBCTL), *args], cwd=cwd, input=stdin, capture_output=True, text=True, timeout=300, check=False
    )


def test_capture_and_station_from_a_folder_of_decoys(sqlite_url: str, forty: Path, decoys: Path) -> None:
    assert CALIBCTL.exists(), CALIBCTL
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    captured = _calibctl(
        decoys,
        "--db",
        sqlite_url,
        "capture",
        "--board",
        "A17",
        "--source",
        str(forty),
        "--serial",
        "CAM-1",
        "-j",
        "2",
    )
    assert captured.returncode == 0, captured.stdout + captured.stderr
    assert f"{VIEWS} image(s) kept" in captured.stdout
    shots = forty.parent
    station = _calibctl(
        decoys,
        "--db",
        sqlite_url,
        "station",
        "--board",
        "A17",
        "--source-template",
        f"{shots}/{{serial}}",
        "--json",
        "-j",
        "2",
        stdin="CAM-1\n",
    )
    assert station.returncode == 0, station.stdout + station.stderr
    (line,) = [json.loads(x) for x in station.stdout.splitlines() if x.strip()]
    assert line["serial"] == "CAM-1" and line["status"] not in ("error", "cancelled"), line
    assert "Traceback" not in station.stderr
    assert sorted(p.name for p in decoys.iterdir()) == [
        "calibctl",
        "cv2.py",
        "numpy",
    ]  # nothing written there
    shutil.rmtree(decoys)
