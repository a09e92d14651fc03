"""What each command loads: the CLI imports a command's module when it runs, and its workflows inside the
command.

The cost of these imports is measured in benchmarks/bench_e2e.py (CLI start-up), not asserted; this
only checks which modules a bare ``import calibctl.cli.main`` pulls in, in a fresh interpreter.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from calibctl.cli import registry

HEAVY = ("matplotlib", "sqlalchemy", "alembic", "cv2", "pydantic", "calibctl.workflows", "calibctl.store")


def _modules_after(code: str) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport sys, json; print(json.dumps(sorted(sys.modules)))"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return set(json.loads(out.strip().splitlines()[-1]))


COMMAND_MODULES = sorted({f"calibctl.cli.{m}" for m in registry.COMMAND_MODULES.values()})


def test_importing_the_cli_and_making_the_root_loads_no_command_module() -> None:
    loaded = _modules_after(
        "import typer.main\nfrom calibctl.cli.main import app\ntyper.main.get_command(app)"
    )
    assert "typer" in loaded
    assert sorted(m for m in loaded if m in COMMAND_MODULES) == []  # each is imported when its command runs
    assert sorted(m for m in loaded if m.split(".")[0] in HEAVY or m.startswith(HEAVY)) == []


def test_the_help_loads_every_command_module_and_no_workflow_store_or_plotting_module() -> None:
    loaded = _modules_after(
        "import typer.main\nfrom calibctl.cli.main import app\n"
        "typer.main.get_command(app).main(['--help'], standalone_mode=False)"
    )
    assert sorted(m for m in loaded if m in COMMAND_MODULES) == COMMAND_MODULES
    assert sorted(m for m in loaded if m.split(".")[0] in HEAVY or m.startswith(HEAVY)) == []


def test_the_diagnostics_workflow_loads_matplotlib_only_to_draw() -> None:
    loaded = _modules_after("import calibctl.workflows.diagnostics.diagnostics")
    assert "calibctl.workflows.diagnostics.diagnostics" in loaded
    assert not any(m.split(".")[0] == "matplotlib" for m in loaded)


# What a read command must not load: alembic (with mako and pygments) is only for migrating, cv2 only
# for images, matplotlib only for --plot, psycopg and the PostgreSQL dialect only for a PostgreSQL URL.
NOT_FOR_READING = (
    "alembic",
    "mako",
    "pygments",
    "cv2",
    "matplotlib",
    "psycopg",
    "sqlalchemy.dialects.postgresql",
)
REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def migrated_store(tmp_path_factory) -> str:
    url = f"sqlite:///{tmp_path_factory.mktemp('startup') / 'store.db'}"
    from calibctl.store.migrate import upgrade_url

    upgrade_url(url)
    return url


@pytest.mark.parametrize(
    "args",
    [
        ["board", "list"],
        ["history", "CAM-1"],
        ["show", "CAM-1"],
        ["export", "CAM-1"],
        ["db", "current"],
        ["lint", str(REPO / "fixtures/camera_front.json")],
    ],
)
def test_read_commands_load_no_migration_image_plot_or_postgres_module(migrated_store, args) -> None:
    code = (
        "import typer.main\nfrom calibctl.cli.main import app\n"
        f"try:\n    typer.main.get_command(app).main({['--db', migrated_store, *args]!r}, "
        "standalone_mode=False)\n"
        "except BaseException:\n    pass"
    )  # the exit code is not the point here: the imports are
    loaded = _modules_after(code)
    assert loaded & {"calibctl.store.repository", "calibctl.store.sqlite_reads"} or args[0] == "lint"
    assert sorted(m for m in loaded if m.startswith(NOT_FOR_READING)) == []
    # Only the module that registers the command is imported (calibctl.cli.registry), not the other 12.
    assert sorted(m for m in loaded if m in COMMAND_MODULES) == [
        f"calibctl.cli.{registry.COMMAND_MODULES[args[0]]}"
    ]


# What reading a SQLite store needs is sqlite3, the artifact models and rich (calibctl.store.sqlite_reads):
# not sqlalchemy (the ORM is for writes, PostgreSQL and the error paths), not numpy or the lens checks (only
# lint computes on the numbers), not cryptography (only signing and verifying signatures), not the
# whole-store audit (`db verify`) nor the rig models, not yaml (only a YAML file or export).
NOT_FOR_STORE_READS = (
    "sqlalchemy",
    "calibctl.store.repository",
    "numpy",
    "cryptography",
    "calibctl.workflows.lint.lint",
    "calibctl.store.audit",
    "calibctl.artifacts.rig",
    "yaml",
)


@pytest.fixture(scope="module")
def store_with_a_calibration(migrated_store) -> str:
    from calibctl.store.repository import Store
    from tests.artifacts.factories import calibration, measured_board

    with Store.open(migrated_store) as store:
        store.add_board(measured_board())  # `board list` reads a row
        store.add_artifact(
            calibration(serial="CAM-1"), activate=True, actor="qa", station="st1", reason="solved"
        )
    return migrated_store


def _run_loading(args: list[str]) -> set[str]:
    return _run(args)[0]


def _run(args: list[str]) -> tuple[set[str], str]:
    """The modules loaded by running ``calibctl ARGS`` in a fresh interpreter, and what it printed."""
    code = (
        "import typer.main\nfrom calibctl.cli.main import app\n"
        f"try:\n    typer.main.get_command(app).main({args!r}, "
        "standalone_mode=False)\nexcept BaseException as exc:\n    raise SystemExit(f'failed: {exc!r}')"
        "\nimport sys, json; print(json.dumps(sorted(sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    printed, _, modules = out.rstrip("\n").rpartition("\n")
    return set(json.loads(modules)), printed


@pytest.mark.parametrize(
    "args",
    [
        ["board", "list"],
        ["history", "CAM-1"],
        ["show", "CAM-1"],
        ["export", "CAM-1"],
        ["show", "CAM-1", "--json"],
    ],
)
def test_sqlite_store_reads_load_no_orm_numpy_crypto_audit_rig_or_yaml_module(
    store_with_a_calibration, args
) -> None:
    loaded = _run_loading(["--db", store_with_a_calibration, *args])
    assert "calibctl.store.sqlite_reads" in loaded
    assert sorted(m for m in loaded if m.startswith(NOT_FOR_STORE_READS)) == []


# Building the pydantic models is most of a read command's own start-up (benchmarks/results/startup.md): each
# read builds the models of what it reads. The calibration models (with the session and check ones they use)
# are not for boards; the writers' modules (formats, the trace header, ROS camera_info) are not for history or
# show, and a JSON export, the default, stamps no trace header; the served-record check (signing's chain
# specs) runs with trusted keys only, and history reads no keys.
CALIBRATION_MODELS = (
    "calibctl.artifacts.calibration",
    "calibctl.artifacts.session",
    "calibctl.artifacts.check",
)
EXPORT_WRITERS = (
    "calibctl.workflows.exports.formats",
    "calibctl.workflows.exports.trace_header",
    "calibctl.workflows.exports.ros_camera_info",
)


def test_board_list_builds_the_board_model_and_no_calibration_session_or_check_model(
    store_with_a_calibration,
) -> None:
    loaded, printed = _run(["--db", store_with_a_calibration, "board", "list"])
    assert (
        "A17" in printed and "calibctl.artifacts.board" in loaded and "calibctl.store.sqlite_reads" in loaded
    )
    assert sorted(m for m in loaded if m in CALIBRATION_MODELS) == []


@pytest.mark.parametrize("args", [["history", "CAM-1"], ["show", "CAM-1"], ["show", "CAM-1", "--json"]])
def test_history_and_show_load_no_export_writer_and_without_keys_no_served_record_check(
    store_with_a_calibration, args
) -> None:
    loaded, printed = _run(["--db", store_with_a_calibration, *args])
    assert "CAM-1" in printed and "calibctl.artifacts.calibration" in loaded
    assert sorted(m for m in loaded if m in (*EXPORT_WRITERS, "calibctl.store.served")) == []
    if args[0] == "history":  # nor the keys (show reads the trusted ones: without any, none is loaded)
        assert (
            sorted(m for m in loaded if m in ("calibctl.workflows.store_admin.keys", "calibctl.signing"))
            == []
        )


def test_a_json_export_loads_formats_but_no_trace_header_or_ros_writer(store_with_a_calibration) -> None:
    loaded, printed = _run(["--db", store_with_a_calibration, "export", "CAM-1"])
    assert json.loads(printed)["serial"] == "CAM-1" and "calibctl.workflows.exports.formats" in loaded
    assert sorted(m for m in loaded if m in EXPORT_WRITERS[1:]) == []
    loaded, printed = _run(["--db", store_with_a_calibration, "export", "CAM-1", "--format", "ros"])
    assert "camera_matrix" in printed and set(EXPORT_WRITERS) <= loaded


def test_linting_a_camera_file_builds_no_rig_hand_eye_or_lidar_model() -> None:
    loaded, printed = _run(["lint", str(REPO / "fixtures/camera_front.json")])
    assert "pass" in printed and "calibctl.workflows.lint.rig_files" in loaded
    assert (
        sorted(
            m
            for m in loaded
            if m.startswith(
                ("calibctl.artifacts.rig", "calibctl.artifacts.handeye", "calibctl.artifacts.lidar")
            )
        )
        == []
    )


def test_an_export_prints_its_text_without_loading_rich(store_with_a_calibration) -> None:
    loaded = _run_loading(["--db", store_with_a_calibration, "export", "CAM-1"])
    assert "calibctl.cli.artifacts" in loaded
    assert (
        sorted(
            m
            for m in loaded
            if m.split(".")[0] == "rich" or m in ("calibctl.cli.render", "calibctl.cli.report")
        )
        == []
    )


def test_a_ros_export_loads_yaml_to_write_it_and_nothing_else_a_read_does_not(
    store_with_a_calibration,
) -> None:
    loaded = _run_loading(["--db", store_with_a_calibration, "export", "CAM-1", "--format", "ros"])
    assert "yaml" in loaded
    assert sorted(m for m in loaded if m.startswith(NOT_FOR_STORE_READS) and m.split(".")[0] != "yaml") == []


def test_linting_a_json_file_loads_numpy_but_no_yaml_store_crypto_or_rich_module() -> None:
    # lint's rules (the distortion fold-over scan, the principal point, ...) compute with numpy: it stays.
    # Its text prints through calibctl.cli.plain_text, so neither rich nor the rich renderers load.
    for fmt in ("text", "json", "github"):
        loaded = _run_loading(["lint", str(REPO / "fixtures/camera_front.json"), "--format", fmt])
        assert "numpy" in loaded and "calibctl.workflows.lint.lint" in loaded
        assert (
            sorted(
                m
                for m in loaded
                if m.startswith(
                    (
                        "yaml",
                        "sqlalchemy",
                        "calibctl.store",
                        "cryptography",
                        "rich",
                        "calibctl.cli.render",
                        "calibctl.cli.report",
                    )
                )
            )
            == []
        )


NUMPY_BLAS_THREADS = """
import os
from threadpoolctl import threadpool_info
def numpy_blas_threads():  # numpy's own OpenBLAS (cv2 bundles another)
    return next((lib["num_threads"] for lib in threadpool_info() if "numpy" in lib["filepath"]), None)
print(numpy_blas_threads(), os.environ.get("OPENBLAS_NUM_THREADS"))
"""


def _numpy_blas_threads_after(code: str, openblas_env: str | None = None) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if openblas_env is not None:
        env["OPENBLAS_NUM_THREADS"] = openblas_env
    out = subprocess.run(
        [sys.executable, "-c", code + NUMPY_BLAS_THREADS], capture_output=True, text=True, check=True, env=env
    ).stdout
    return out.strip().splitlines()[-1].split()


LINT_FILE = (
    "import typer.main\nfrom calibctl.cli.main import app\ntry:\n    typer.main.get_command(app).main("
    f"['lint', {str(REPO / 'fixtures/camera_front.json')!r}], standalone_mode=False)\nexcept SystemExit:\n "
    "   pass"
)


def test_lint_starts_numpys_openblas_on_one_thread_and_leaves_the_environment_and_solving_imports_alone() -> (
    None
):
    default, _ = _numpy_blas_threads_after("import numpy")
    if default == "None":
        pytest.skip("no bundled OpenBLAS found in this environment")
    if default == "1":
        pytest.skip("OpenBLAS starts on one thread here anyway (one CPU), so lint's choice cannot show")
    assert _numpy_blas_threads_after(LINT_FILE) == ["1", "None"]  # one thread; the variable is gone again
    # The workflows imported any other way (as every solving command does) keep OpenBLAS's own count.
    assert _numpy_blas_threads_after(
        "import calibctl.workflows.lint.lint, calibctl.workflows.camera.solve"
    ) == [default, "None"]
    assert _numpy_blas_threads_after(LINT_FILE, openblas_env=default) == [
        default,
        default,
    ]  # the user's count stays


PLUGIN_SCANS = """
import importlib.metadata, os, sys
# calls made by pydantic's plugin loader: entry_points(group=...) (pydantic 2.10+), distributions() (older)
scans = []
def counting(real):
    def call(*args, **kwargs):
        if sys._getframe(1).f_globals.get("__name__") == "pydantic.plugin._loader":
            scans.append(real.__name__)
        return real(*args, **kwargs)
    return call
importlib.metadata.entry_points = counting(importlib.metadata.entry_points)  # before the loader imports them
importlib.metadata.distributions = counting(importlib.metadata.distributions)
sys.argv = ["calibctl", *sys.argv[1:]]
from calibctl.cli.main import run
try:
    run()
except SystemExit as exc:
    assert exc.code == 0, exc.code
print(min(len(scans), 1), repr(os.environ.get("PYDANTIC_DISABLE_PLUGINS")))
"""


@pytest.mark.parametrize(("user_value", "scans", "value"), [(None, "0", "'__all__'"), ("", "1", "''")])
def test_the_command_line_skips_pydantics_plugin_scan_unless_the_user_set_the_variable(
    store_with_a_calibration, user_value, scans, value
) -> None:
    # calibctl's models use no pydantic plugin: the scan reads every installed distribution's entry points.
    env = {k: v for k, v in os.environ.items() if k != "PYDANTIC_DISABLE_PLUGINS"}
    if user_value is not None:
        env["PYDANTIC_DISABLE_PLUGINS"] = user_value  # "" turns plugins back on: pydantic scans
    out = subprocess.run(
        [sys.executable, "-c", PLUGIN_SCANS, "--db", store_with_a_calibration, "history", "CAM-1"],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    ).stdout
    assert "CAM-1" in out
    assert out.strip().splitlines()[-1].split() == [scans, value]
