"""PostgreSQL (psycopg) and plotting (matplotlib) are extras: without them, a clear exit 2, no traceback.

A missing package is simulated with ``sys.modules[name] = None`` (Python then refuses the import),
so the suite needs no second virtualenv to prove the message.
"""

from __future__ import annotations

import shlex
import sys
import tomllib
from pathlib import Path

from typer.testing import CliRunner

import calibctl.workflows.diagnostics
from calibctl.cli.main import app
from calibctl.errors import EXTRA_PACKAGES

runner = CliRunner()


def _hide(monkeypatch, package: str) -> None:
    """Make ``package`` and every submodule already imported by earlier tests unimportable."""
    for name in [n for n in sys.modules if n == package or n.startswith(f"{package}.")] + [package]:
        monkeypatch.setitem(sys.modules, name, None)


def _assert_missing_extra(res, extra: str, package: str, purpose: str) -> None:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and res.stdout == ""
    assert f"Error: {purpose} needs the Python package {package}, which is not installed" in res.stderr
    hint = res.stderr[res.stderr.index("Hint:") :]
    spec = EXTRA_PACKAGES[extra]
    assert f"pipx inject calibctl '{spec}'" in hint
    assert f"uv tool install --with '{spec}' ./calibctl-0.1.0-py3-none-any.whl" in hint
    # never a package name no index holds (whoever published calibctl[...] would get their code installed)
    assert "calibctl[" not in hint and "pipx install" not in hint


def test_the_hints_name_what_pyproject_declares_and_parse_as_shell_words():
    declared = tomllib.loads((Path(__file__).parents[3] / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    for extra, spec in EXTRA_PACKAGES.items():
        assert declared[extra] == [spec]
        assert shlex.split(f"pipx inject calibctl '{spec}'") == ["pipx", "inject", "calibctl", spec]


def test_a_postgresql_store_without_psycopg_names_the_postgres_extra(monkeypatch):
    _hide(monkeypatch, "psycopg")
    res = runner.invoke(app, ["--db", "postgresql://calib:secret@factory-db/calibctl", "db", "current"])
    _assert_missing_extra(
        res, "postgres", "psycopg", "the PostgreSQL store postgresql://calib:***@factory-db/calibctl"
    )


def test_plot_without_matplotlib_names_the_plots_extra(monkeypatch, tmp_path):
    csv = tmp_path / "in.csv"
    assert (
        runner.invoke(app, ["synth-residuals", str(csv), "--fault", "rotation", "--seed", "2"]).exit_code == 0
    )
    _hide(monkeypatch, "matplotlib")
    monkeypatch.delitem(sys.modules, "calibctl.workflows.diagnostics.diagnostics_plots", raising=False)
    monkeypatch.delattr(calibctl.workflows.diagnostics, "diagnostics_plots", raising=False)  # re-import it
    res = runner.invoke(app, ["triage", str(csv), "--plot", str(tmp_path / "plots")])
    _assert_missing_extra(res, "plots", "matplotlib", "--plot")
    assert not list(tmp_path.glob("plots/*.png"))


def test_without_extras_a_sqlite_store_still_works(monkeypatch, tmp_path):
    _hide(monkeypatch, "psycopg")
    _hide(monkeypatch, "matplotlib")
    res = runner.invoke(app, ["--db", f"sqlite:///{tmp_path / 's.db'}", "db", "upgrade"])
    assert res.exit_code == 0, res.output
