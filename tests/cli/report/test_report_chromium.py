"""The report opened by a real browser: headless Chromium (Debian's package; `make test-slow` installs it)
renders the real opencv-left-right report without a console message, and its screenshot is not blank.
The screenshot is kept in the test's tmp dir for a person to look at."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from tests.cli.real_left import calibrated_left_store

pytestmark = pytest.mark.slow
INK_FRACTION = 0.02  # a blank or unstyled-error page has (almost) no non-white pixels


def chromium() -> str:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        message = "chromium not installed (apt-get install -y chromium; `make test-slow` does it)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    return found


def screenshot(page: Path, png: Path) -> list[str]:
    """Render ``page`` into ``png``; the browser's console messages (console.* and script errors)."""
    done = subprocess.run(
        [
            chromium(),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--enable-logging=stderr",
            "--v=0",
            f"--user-data-dir={png.parent / 'chromium-profile'}",
            "--window-size=1100,3800",
            f"--screenshot={png}",
            page.resolve().as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0 and png.is_file(), done.stderr[-2000:]
    return [line for line in done.stderr.splitlines() if ":CONSOLE" in line]


def ink(png: Path) -> float:
    image = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    return float(np.mean(image < 200))


def test_the_console_check_catches_a_script_error(tmp_path):
    page = tmp_path / "broken.html"
    page.write_text(
        '<html><body><script>console.error("report-test")</script></body></html>', encoding="utf-8"
    )
    messages = screenshot(page, tmp_path / "broken.png")
    assert any("report-test" in m for m in messages)
    assert ink(tmp_path / "broken.png") < INK_FRACTION


def test_the_real_report_renders_in_chromium(tmp_path):
    url = calibrated_left_store(tmp_path, "LEFT-01")
    page = tmp_path / "report.html"
    assert CliRunner().invoke(app, ["--db", url, "report", "LEFT-01", "-o", str(page)]).exit_code == 0
    png = tmp_path / "report.png"
    assert screenshot(page, png) == []
    assert ink(png) > INK_FRACTION
