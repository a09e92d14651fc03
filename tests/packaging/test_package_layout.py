"""What the wheel ships: every calibctl package, and the migrations found in a wheel and a checkout."""

from __future__ import annotations

import tomllib
from pathlib import Path

from calibctl.store import migrate

REPO = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))


def test_pyproject_lists_every_calibctl_package_and_ships_the_migrations():
    found = {
        ".".join(init.parent.relative_to(REPO).parts) for init in (REPO / "calibctl").rglob("__init__.py")
    }
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    assert listed - found == {"calibctl._migrations", "calibctl._migrations.versions"}
    assert found <= listed, f"add {sorted(found - listed)} to [tool.setuptools] packages in pyproject.toml"
    assert PYPROJECT["tool"]["setuptools"]["package-dir"] == {"calibctl._migrations": "migrations"}


def test_a_wheel_finds_its_packaged_migrations_first(tmp_path):
    package_root = tmp_path / "site-packages" / "calibctl"
    (package_root / "_migrations").mkdir(parents=True)
    (package_root / "_migrations" / "env.py").write_text("", encoding="utf-8")
    assert migrate.migrations_dir(package_root) == package_root / "_migrations"


def test_a_checkout_finds_the_top_level_migrations(tmp_path):
    assert migrate.migrations_dir(tmp_path / "calibctl") == tmp_path / "migrations"
    assert migrate.MIGRATIONS_DIR == REPO / "migrations"
    assert migrate.ALEMBIC_INI.is_file()


def test_postgres_and_plots_are_extras_not_requirements():
    project = PYPROJECT["project"]
    names = " ".join(project["dependencies"])
    assert "psycopg" not in names and "matplotlib" not in names
    assert project["optional-dependencies"]["postgres"] == ["psycopg[binary]>=3.1.4"]
    assert project["optional-dependencies"]["plots"] == ["matplotlib>=3.8"]
