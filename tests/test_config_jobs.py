"""Detection workers: --jobs > CALIBCTL_JOBS > the station file's jobs > the cores this process may use."""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.config import load_settings
from calibctl.core.blas_threads import available_cores
from calibctl.errors import InputError, UsageError


def station_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "station.yaml"
    path.write_text(text)
    return path


def test_jobs_come_from_the_flag_then_the_environment_then_the_station_file_then_the_cores(
    tmp_path: Path,
) -> None:
    db = f"sqlite:///{tmp_path / 'c.db'}"
    cfg = station_file(tmp_path, "jobs: 3\n")
    assert load_settings(db=db, station_config=cfg, env={"CALIBCTL_JOBS": "5"}, jobs=7).jobs == 7
    assert load_settings(db=db, station_config=cfg, env={"CALIBCTL_JOBS": "5"}).jobs == 5
    assert load_settings(db=db, station_config=cfg, env={}).jobs == 3
    assert load_settings(db=db, env={}).jobs == available_cores()


@pytest.mark.parametrize("value", ["0", "two", "-1", "1.5"])
def test_a_bad_calibctl_jobs_is_a_usage_error_naming_the_variable(tmp_path: Path, value: str) -> None:
    with pytest.raises(
        UsageError, match=f"CALIBCTL_JOBS must be a whole number of 1 or more, got '{value}'"
    ) as info:
        load_settings(db=f"sqlite:///{tmp_path / 'c.db'}", env={"CALIBCTL_JOBS": value})
    assert info.value.exit_code == 2 and "unset it" in (info.value.hint or "")


def test_a_station_file_with_jobs_below_one_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="jobs: Input should be greater than or equal to 1"):
        load_settings(
            db=f"sqlite:///{tmp_path / 'c.db'}", station_config=station_file(tmp_path, "jobs: 0\n"), env={}
        )


def test_a_flag_below_one_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="--jobs must be 1 or more, got 0"):
        load_settings(db=f"sqlite:///{tmp_path / 'c.db'}", env={}, jobs=0)
