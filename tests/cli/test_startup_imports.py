"""What `calibctl --help` / `--version` load: the CLI imports its workflows inside the commands.

The cost of these imports is measured in benchmarks/bench_e2e.py (CLI start-up), not asserted; this
only checks which modules a bare ``import calibctl.cli.main`` pulls in, in a fresh interpreter.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("matplotlib", "sqlalchemy", "alembic", "cv2", "pydantic", "calibctl.workflows", "calibctl.store")


def _modules_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", f"{code}\nimport sys, json; print(json.dumps(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True).stdout
    return set(json.loads(out.strip().splitlines()[-1]))


def test_importing_the_cli_loads_no_workflow_store_or_plotting_module() -> None:
    loaded = _modules_after("import calibctl.cli.main")
    assert "calibctl.cli.capture" in loaded and "typer" in loaded  # the commands are registered
    assert sorted(m for m in loaded if m.split(".")[0] in HEAVY or m.startswith(HEAVY)) == []


def test_the_diagnostics_workflow_loads_matplotlib_only_to_draw() -> None:
    loaded = _modules_after("import calibctl.workflows.diagnostics")
    assert "calibctl.workflows.diagnostics" in loaded
    assert not any(m.split(".")[0] == "matplotlib" for m in loaded)


# What a read command must not load: alembic (with mako and pygments) is only for migrating, cv2 only
# for images, matplotlib only for --plot, psycopg and the PostgreSQL dialect only for a PostgreSQL URL.
NOT_FOR_READING = ("alembic", "mako", "pygments", "cv2", "matplotlib", "psycopg", "sqlalchemy.dialects.postgresql")
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def migrated_store(tmp_path_factory) -> str:
    url = f"sqlite:///{tmp_path_factory.mktemp('startup') / 'store.db'}"
    from calibctl.store.migrate import upgrade_url

    upgrade_url(url)
    return url


@pytest.mark.parametrize("args", [
    ["board", "list"], ["history", "CAM-1"], ["show", "CAM-1"], ["export", "CAM-1"], ["db", "current"],
    ["lint", str(REPO / "fixtures/camera_front.json")],
])
def test_read_commands_load_no_migration_image_plot_or_postgres_module(migrated_store, args) -> None:
    code = ("import typer.main\nfrom calibctl.cli.main import app\n"
            f"try:\n    typer.main.get_command(app).main({['--db', migrated_store, *args]!r}, standalone_mode=False)\n"
            "except BaseException:\n    pass")  # the exit code is not the point here: the imports are
    loaded = _modules_after(code)
    assert loaded & {"calibctl.store.repository", "calibctl.store.sqlite_reads"} or args[0] == "lint"
    assert sorted(m for m in loaded if m.startswith(NOT_FOR_READING)) == []


# What reading a SQLite store needs is sqlite3, the artifact models and rich (calibctl.store.sqlite_reads):
# not sqlalchemy (the ORM is for writes, PostgreSQL and the error paths), not numpy or the lens checks (only
# lint computes on the numbers), not cryptography (only signing and verifying signatures), not the
# whole-store audit (`db verify`) nor the rig models.
NOT_FOR_STORE_READS = ("sqlalchemy", "calibctl.store.repository", "numpy", "cryptography", "calibctl.workflows.lint", "calibctl.store.audit",
                       "calibctl.artifacts.rig")


@pytest.fixture(scope="module")
def store_with_a_calibration(migrated_store) -> str:
    from calibctl.store.repository import Store
    from tests.artifacts.factories import calibration

    with Store.open(migrated_store) as store:
        store.add_artifact(calibration(serial="CAM-1"), activate=True, actor="qa", station="st1", reason="solved")
    return migrated_store


@pytest.mark.parametrize("args", [
    ["board", "list"], ["history", "CAM-1"], ["show", "CAM-1"], ["export", "CAM-1"],
    ["export", "CAM-1", "--format", "ros"],
])
def test_sqlite_store_reads_load_no_orm_numpy_crypto_audit_or_rig_module(store_with_a_calibration, args) -> None:
    code = ("import typer.main\nfrom calibctl.cli.main import app\n"
            f"try:\n    typer.main.get_command(app).main({['--db', store_with_a_calibration, *args]!r}, "
            "standalone_mode=False)\nexcept BaseException as exc:\n    raise SystemExit(f'failed: {exc!r}')")
    loaded = _modules_after(code)
    assert "calibctl.store.sqlite_reads" in loaded
    assert sorted(m for m in loaded if m.startswith(NOT_FOR_STORE_READS)) == []
