"""The spool tests' central SQLite store (board A17), the station's settings for it and the unit folders."""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.config import load_settings
from tests.workflows.station.spool_setup import central_folder, unit_folders


@pytest.fixture
def central(tmp_path: Path) -> Path:
    return central_folder(tmp_path)


@pytest.fixture
def settings(central: Path):
    return load_settings(
        db=f"sqlite:///{central / 'calibctl.db'}", station="line-3", operator="op-ana", env={}, jobs=2
    )


@pytest.fixture
def shots(tmp_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return unit_folders(tmp_path_factory, tmp_path)
