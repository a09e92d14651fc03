"""The wheel users install with pip, pipx or uv: built from the sources, installed into a fresh
virtualenv outside the repository (no extras), it runs ``calibctl demo`` and ``calibctl db upgrade``.

Dependencies come from the package index at the versions of constraints/lock.txt (what
``make install`` uses, so pip's cache usually serves them), installed by the test's own pip.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
WHEEL_SOURCES = ("pyproject.toml", "README.md", "calibctl", "migrations")


def _env() -> dict[str, str]:
    """No PYTHONPATH (it would import the checkout) and no developer CALIBCTL_* settings."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH" and not k.startswith("CALIBCTL_")}


def _run(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(a) for a in args], cwd=cwd, env=_env(), capture_output=True, text=True, check=False
    )


@pytest.fixture(scope="module")
def venv_bin(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("wheel")
    src = root / "src"
    src.mkdir()
    for name in WHEEL_SOURCES:
        origin = REPO / name
        if origin.is_dir():
            shutil.copytree(origin, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(origin, src / name)
    built = _run(sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", root / "dist", src, cwd=root)
    assert built.returncode == 0, built.stderr
    assert "deprecated" not in built.stderr.lower(), built.stderr  # e.g. the old license table
    (wheel,) = (root / "dist").glob("calibctl-*.whl")
    # The venv gets no pip of its own (ensurepip is most of a venv's start): this process's pip installs
    # into it (--python).
    created = _run(sys.executable, "-m", "venv", "--without-pip", root / "venv", cwd=root)
    assert created.returncode == 0, created.stderr
    installed = _run(
        sys.executable,
        "-m",
        "pip",
        "--python",
        root / "venv/bin/python",
        "install",
        "--quiet",
        "-c",
        REPO / "constraints/lock.txt",
        wheel,
        cwd=root,
    )
    assert installed.returncode == 0, installed.stderr
    return root / "venv/bin"


def test_the_installed_wheel_is_what_runs_and_ships_its_migrations(venv_bin):
    code = "import calibctl.store.migrate as m; print(m.__file__); print(m.MIGRATIONS_DIR)"
    out = _run(venv_bin / "python", "-c", code, cwd=venv_bin.parent.parent)
    assert out.returncode == 0, out.stderr
    module_file, migrations = out.stdout.split()
    site = venv_bin.parent / "lib"
    assert Path(module_file).is_relative_to(site) and Path(migrations).is_relative_to(site)
    assert sorted(p.name for p in Path(migrations, "versions").glob("*.py")) == sorted(
        p.name for p in (REPO / "migrations/versions").glob("*.py")
    )


def test_the_extras_are_not_installed_by_default(venv_bin):
    for module in ("psycopg", "matplotlib"):
        out = _run(venv_bin / "python", "-c", f"import {module}", cwd=venv_bin.parent.parent)
        assert out.returncode == 1 and "ModuleNotFoundError" in out.stderr, module


def test_demo_runs_from_the_wheel_outside_the_repository(venv_bin, tmp_path):
    out = _run(venv_bin / "calibctl", "demo", cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "done: DEMO-CAM-0001@1 accepted and active" in out.stdout
    assert (tmp_path / "demo-out/calibctl-demo.db").is_file()


def test_db_upgrade_creates_a_store_at_head_from_the_wheel(venv_bin, tmp_path):
    url = f"sqlite:///{tmp_path / 'station.db'}"
    up = _run(venv_bin / "calibctl", "--db", url, "db", "upgrade", cwd=tmp_path)
    assert up.returncode == 0, up.stdout + up.stderr
    current = _run(venv_bin / "calibctl", "--db", url, "--json", "db", "current", cwd=tmp_path)
    assert current.returncode == 0, current.stderr
    report = json.loads(current.stdout)
    assert report["status"] == "current" and report["current"] == report["head"] is not None
