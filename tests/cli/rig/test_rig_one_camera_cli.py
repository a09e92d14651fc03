"""What needs two cameras refuses a one-camera rig: exit 2, one line naming why, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.workflows.imu.imu_data import CAM, MONO, cli, make_mono_store

SESSION = "fedcba987654"
ONE_CAMERA = "has one camera"


@pytest.fixture(scope="module")
def mono(tmp_path_factory: pytest.TempPathFactory) -> str:
    """Read-only: every command below must leave it as it is (checked by each test)."""
    return make_mono_store(tmp_path_factory.mktemp("rig-mono") / "mono.db")


@pytest.mark.parametrize(
    ("args", "why"),
    [
        (("rig", "capture", MONO, "--source", f"{CAM}=SRC", "--board", "G7"), ONE_CAMERA),
        (("capture", "--rig", MONO, "--source", f"{CAM}=SRC", "--board", "G7"), ONE_CAMERA),
        (("rig", "solve", MONO, SESSION), ONE_CAMERA),
        (("rig", "solve", MONO, "--refine-intrinsics"), ONE_CAMERA),
        (("solve", "--rig", MONO, "--refine-intrinsics"), ONE_CAMERA),
        (("rig", "export", MONO, "--format", "opencv"), ONE_CAMERA),
        (("rig", "export", MONO, "--format", "lut", "-o", "OUT"), ONE_CAMERA),
        (("rig", "export", MONO, "--format", "kalibr", "--pair", CAM), ONE_CAMERA),
        (
            (
                "rig",
                "solve-folders",
                "--source",
                f"{CAM}=SRC",
                "--cols",
                "7",
                "--rows",
                "6",
                "--square-mm",
                "50",
            ),
            "at least two cameras",
        ),
        (
            ("rig", "add", "MONO-2", "--camera", CAM, "--design-baseline-mm", f"{CAM}:{CAM}=75"),
            ONE_CAMERA,
        ),
    ],
    ids=lambda v: " ".join(v[:3]) if isinstance(v, tuple) else None,
)
def test_a_two_camera_command_refuses_a_one_camera_rig_in_one_line(
    mono: str, tmp_path: Path, args: tuple[str, ...], why: str
) -> None:
    (tmp_path / "src").mkdir()
    args = tuple(a.replace("SRC", str(tmp_path / "src")).replace("OUT", str(tmp_path / "out")) for a in args)
    done = cli(mono, *args)
    errors = [line for line in done.output.splitlines() if line.startswith("Error:")]
    assert done.exit_code == 2 and "Traceback" not in done.output, done.output
    assert len(errors) == 1 and why in errors[0], done.output
    assert not (tmp_path / "out").exists()
    history = json.loads(cli(mono, "rig", "history", MONO, "--json").stdout)
    assert [v["version"] for v in history["versions"]] == [1] and history["active_version"] == 1
