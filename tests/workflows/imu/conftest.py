from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.workflows.imu import imu_data


@pytest.fixture(scope="session")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return imu_data.rendered(tmp_path_factory)


@pytest.fixture(scope="session")
def solved(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    return imu_data.solved(tmp_path_factory)
