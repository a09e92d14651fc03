"""Shared camera + IMU test data: a lint-clean rig store and one rendered recording, made once per session.

The recording is rendered through CAM-0001's stored calibration (``imu synth --serial``), so the solve
holds the very intrinsics that made it. ``recording`` and ``solved`` are cached under the session's base
temp folder: the workflow and the CLI tests share one render and one stored solve.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.config import Settings, load_settings
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.rig_documents import RIG, rig_calibration, rig_definition

CAM, OTHER = "CAM-0001", "CAM-0002"
WHO = {"actor": "qa", "station": "st1", "reason": "solved"}
TD_S = 0.012
RUNNER = CliRunner()


def settings_for(url: str) -> Settings:
    return load_settings(db=url, station="st-test", operator="tester", env={})


def make_store(db: Path, other_calibrated: bool = True) -> str:
    """Rig STEREO-1 (frame imu) at version 1 over CAM-0001 (and CAM-0002), members pinned to the stored
    calibrations (lint clean), and the boards G7 (the renders' 7 x 6 inner corners, 50 mm) and G7-40
    (the same at 40 mm); the url."""
    url = f"sqlite:///{db}"
    with Store.open(url) as store:
        for name, square_mm in (("G7", 50.0), ("G7-40", 40.0)):
            store.add_board(
                measured_board(name, square_mm=square_mm).model_copy(update={"cols": 7, "rows": 6})
            )
        serials = (CAM, OTHER) if other_calibrated else (CAM,)
        arts = [store.add_artifact(calibration(serial=s), activate=True, **WHO) for s in serials]
        store.add_rig(rig_definition().model_copy(update={"frames": ["imu"]}))
        base = rig_calibration()
        members = [
            m.model_copy(
                update={
                    "content_sha256": a.content_sha256,
                    "image_size": a.image_size,
                    "camera_matrix": a.camera_matrix,
                    "dist_coeffs": a.dist_coeffs,
                }
            )
            for m, a in zip(base.members, arts, strict=False)
        ] + base.members[len(arts) :]
        store.add_rig_calibration(base.model_copy(update={"members": members}), activate=True, **WHO)
    return url


def cli(url: str, *args: str) -> Any:
    return RUNNER.invoke(app, ["--db", url, *args])


def _cached(base: Path, name: str) -> tuple[Path, bool]:
    folder = base / name
    return folder, (folder / "done").is_file()


def rendered(tmp_path_factory: pytest.TempPathFactory, motion: str = "dance") -> Path:
    """A 6 s recording (20 Hz camera, 200 Hz IMU, td 12 ms) rendered through CAM-0001's calibration;
    ``motion`` "images": a 3 s dance as ASL images of board G7 instead of corner files ("aprilgrid": of
    Kalibr's AprilGrid, truth.json's board)."""
    folder, done = _cached(tmp_path_factory.getbasetemp(), f"imu-{motion}")
    if not done:
        folder.mkdir(exist_ok=True)
        url = make_store(folder / "render.db")
        args = ["imu", "synth", str(folder / "rec"), "--serial", CAM, "--force"]
        if motion in ("images", "aprilgrid"):
            args += ["--images", "--pattern", "aprilgrid" if motion == "aprilgrid" else "chessboard"]
            args += ["--duration-s", "3"]
        else:
            args += ["--motion", motion]
        r = cli(url, *args, "--td-ms", str(TD_S * 1e3))
        assert r.exit_code == 0, r.output
        (folder / "done").write_text("")
    return folder / "rec"


def solved(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """The store after `imu solve REC --serial CAM-0001 --rig STEREO-1` (read it, never write it: copy it
    with ``copy_db``) and the rig version it stored, as `rig export --format json` wrote it."""
    rec = rendered(tmp_path_factory)
    folder, done = _cached(tmp_path_factory.getbasetemp(), "imu-solved")
    if not done:
        folder.mkdir(exist_ok=True)
        url = make_store(folder / "solved.db")
        r = cli(
            url, "imu", "solve", str(rec), "--serial", CAM, "--noise", str(rec / "imu.yaml"), "--rig", RIG
        )
        assert r.exit_code == 0, r.output
        (folder / "rig.json").write_text(cli(url, "rig", "export", RIG, "--format", "json").stdout)
        (folder / "done").write_text("")
    return folder / "solved.db", json.loads((folder / "rig.json").read_text())


def copy_db(db: Path, tmp_path: Path) -> str:
    shutil.copy(db, tmp_path / "c.db")
    return f"sqlite:///{tmp_path / 'c.db'}"


def copy_recording(rec: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(rec, tmp_path / "rec"))


def truth(rec: Path) -> dict[str, Any]:
    return json.loads((rec / "truth.json").read_text())
