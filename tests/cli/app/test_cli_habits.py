"""CLI habits: an example in every --help, shell completion, --version, and no hard wrap in logs."""

from __future__ import annotations

import io
import shlex

import cv2
import numpy
import pytest
import typer.main
from typer.testing import CliRunner

from calibctl.cli.examples import EXAMPLES
from calibctl.cli.main import app
from calibctl.cli.render import _Console

runner = CliRunner()
ROOT = typer.main.get_command(app)


def _commands(cmd=ROOT, path=()):  # every group and command with its path
    yield " ".join(path), cmd
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from _commands(sub, (*path, name))


COMMANDS = dict(_commands())


def _options(cmd) -> set[str]:
    return {opt for p in cmd.params for opt in (*p.opts, *p.secondary_opts) if opt.startswith("-")}


def test_the_examples_table_covers_exactly_the_commands():
    assert set(EXAMPLES) == set(COMMANDS)


@pytest.mark.parametrize("path", sorted(COMMANDS))
def test_every_help_ends_with_examples_that_name_real_options(path):
    res = runner.invoke(app, [*path.split(), "--help"], terminal_width=100)
    assert res.exit_code == 0, res.output
    assert "Examples:\n" in res.stdout
    for example in EXAMPLES[path]:
        assert f"  $ {example}" in res.stdout  # whole lines: \b keeps click from re-wrapping them
        words = shlex.split(example)
        assert words[0] == "calibctl"
        words = words[1:]
        while words and words[0] in _options(ROOT):  # global options before the command
            words = words[2:] if words[0] in ("--db", "--station-config") else words[1:]
        cmd, used = ROOT, []
        while getattr(cmd, "commands", None) and words and words[0] in cmd.commands:
            cmd, used = cmd.commands[words[0]], [*used, words.pop(0)]
        assert " ".join(used) in (path, *[p for p in COMMANDS if p.startswith(path)]), example
        unknown = [w for w in words if w.startswith("-") and w not in _options(cmd)]
        assert unknown == [], f"{example}: {unknown} are not options of `calibctl {' '.join(used)}`"


def test_shell_completion_is_on():
    script = runner.invoke(app, ["--show-completion", "bash"], prog_name="calibctl")
    assert script.exit_code == 0 and "_CALIBCTL_COMPLETE=complete_bash" in script.stdout
    env = {"_CALIBCTL_COMPLETE": "complete_bash", "COMP_WORDS": "calibctl his", "COMP_CWORD": "1"}
    assert runner.invoke(app, [], prog_name="calibctl", env=env).stdout.split() == ["history"]
    env = {"_CALIBCTL_COMPLETE": "complete_bash", "COMP_WORDS": "calibctl export X --fo", "COMP_CWORD": "3"}
    assert set(runner.invoke(app, [], prog_name="calibctl", env=env).stdout.split()) == {
        "--format",
        "--force",
    }


def test_version_names_calibctl_opencv_and_numpy():
    res = runner.invoke(app, ["--version"])
    assert res.exit_code == 0
    assert res.stdout.startswith("calibctl 0.")
    assert f"OpenCV {cv2.__version__}" in res.stdout and f"numpy {numpy.__version__}" in res.stdout


def test_long_lines_are_never_broken_when_the_output_is_not_a_terminal(sqlite_url):
    instrument = "Mitutoyo 500-196 digital calipers, " * 6  # about 210 characters
    res = runner.invoke(
        app,
        [
            "--db",
            sqlite_url,
            "board",
            "add",
            "A17",
            "--cols",
            "9",
            "--rows",
            "6",
            "--square-mm",
            "25.03",
            "--uncertainty-mm",
            "0.02",
            "--instrument",
            instrument,
            "--measured-by",
            "anna-from-the-metrology-lab-" * 4,
            "--measured-on",
            "2026-03-11",
        ],
        terminal_width=80,
    )
    assert res.exit_code == 0, res.output
    listed = runner.invoke(app, ["--db", sqlite_url, "board", "list"], terminal_width=80).stdout
    row = next(line for line in listed.splitlines() if "A17@1" in line)
    assert "2026-03-11 by " + "anna-from-the-metrology-lab-" * 4 in row  # one table row, one line
    shown = runner.invoke(app, ["--db", sqlite_url, "board", "show", "A17"], terminal_width=80).stdout
    assert any(instrument.strip() in line for line in shown.splitlines())


def test_a_terminal_still_wraps_at_its_width():
    out = io.StringIO()
    console = _Console(file=out, force_terminal=True, width=40, color_system=None)
    console.print("word " * 30)
    assert max(len(line) for line in out.getvalue().splitlines()) <= 40
    piped = io.StringIO()
    _Console(file=piped, color_system=None).print("word " * 30)
    assert piped.getvalue() == "word " * 30 + "\n"
