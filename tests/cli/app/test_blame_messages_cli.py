"""Messages name the real mistake: each input below was refused before, but its message blamed something
else."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.errors import InputError
from calibctl.store.repository import Store
from calibctl.workflows.lidar.camera import lens_from_camera_info
from tests.artifacts.factories import calibration, measured_board


@pytest.fixture
def db(sqlite_url: str) -> str:
    with Store.open(sqlite_url) as store:
        store.add_artifact(
            calibration(serial="CAM-1"), activate=True, actor="qa", station="st1", reason="solved"
        )
    return sqlite_url


@pytest.mark.parametrize(
    "args",
    [["diff", "CAM-1@x", "CAM-1@1"], ["show", "CAM-1@x"], ["export", "CAM-1@", "--format", "json"]],
)
def test_a_malformed_version_is_named_not_an_unknown_serial(db: str, args: list[str]) -> None:
    res = CliRunner().invoke(app, ["--db", db, *args])
    assert res.exit_code == 2, res.output
    assert "the version after '@' is" in res.stderr and "not a number" in res.stderr
    assert "unknown serial" not in res.output and "CAM-1@N" in res.stderr


def test_a_camera_info_with_k_all_zeros_is_named_not_blamed_on_the_poses(tmp_path: Path) -> None:
    info = tmp_path / "camera_info.yaml"
    info.write_text(
        "width: 640\nheight: 480\ndistortion_model: plumb_bob\nK: [0, 0, 0, 0, 0, 0, 0, 0, 0]\n"
        "D: [0, 0, 0, 0, 0]\n"
    )
    with pytest.raises(InputError, match=r"camera_info.yaml: K is not a camera matrix \(fx 0, fy 0"):
        lens_from_camera_info(info)


def test_a_scanned_serial_with_escape_sequences_is_shown_escaped(sqlite_url: str, tmp_path: Path) -> None:
    with Store.open(sqlite_url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    args = ["--db", sqlite_url, "station", "--board", "A17", "--source-template", f"{tmp_path}/{{serial}}"]
    for extra in ([], ["--json"]):
        res = CliRunner().invoke(app, [*args, *extra], input="CAM\x1b[2J-1\n")
        assert res.exit_code == 0, res.output
        assert "\x1b" not in res.output and "CAM\\x1b[2J-1" in res.stdout.replace("\\\\", "\\")
