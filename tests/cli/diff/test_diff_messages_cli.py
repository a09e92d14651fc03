"""calibctl diff's refusals name the real mistake: a malformed version is not an unknown serial."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app


@pytest.mark.parametrize("ref", ["CAM@x", "CAM@", "CAM@3.0"])
def test_a_malformed_version_is_named_not_an_unknown_serial(sqlite_url: str, ref: str) -> None:
    result = CliRunner().invoke(app, ["--db", sqlite_url, "diff", ref, "CAM@1"])
    assert result.exit_code == 2, result.output
    assert f"'{ref}' is not SERIAL or SERIAL@N: the version" in result.stderr
    assert "is not a whole number" in result.stderr and "unknown serial" not in result.stderr
    assert "calibctl history CAM" in result.stderr
