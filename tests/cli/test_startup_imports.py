"""What `calibctl --help` / `--version` load: the CLI imports its workflows inside the commands.

The cost of these imports is measured in benchmarks/bench_e2e.py (CLI start-up), not asserted; this
only checks which modules a bare ``import calibctl.cli.main`` pulls in, in a fresh interpreter.
"""

from __future__ import annotations

import json
import subprocess
import sys

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
