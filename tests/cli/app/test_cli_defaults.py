"""The CLI's defaults are the workflows': a default the CLI leaves to a workflow is named in the help with
the workflow's number, and a default the CLI shows itself (typer's [default: ...]) is the workflow's constant.

The command modules may not import a workflow while the help is made (test_startup_imports), so the help
text cannot read these numbers; these tests keep the two equal instead."""

from __future__ import annotations

import click
import pytest
import typer.main
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.cli.station import _watch_rule
from calibctl.core.intrinsics.solve import DEFAULT_MODEL
from calibctl.workflows.station.station import StationRequest
from calibctl.workflows.station.watch import WatchRule
from calibctl.workflows.synth.synth import DEFAULT_VIDEO_KEYS, DEFAULT_VIEWS
from calibctl.workflows.synth.synth_rig import DEFAULT_RIG_FRAMES

RUNNER = CliRunner()


def _help(*command: str) -> str:
    result = RUNNER.invoke(app, [*command, "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    return " ".join(result.output.split())  # the help's line breaks fall anywhere


def _params(name: str) -> dict[str, object]:
    root = typer.main.get_command(app)
    command = root.get_command(click.Context(root), name)  # type: ignore[attr-defined]
    return {p.name: p.default for p in command.params}


def test_the_station_help_names_the_watch_rules_own_waits() -> None:
    rule = WatchRule(views=1)
    shown = _help("station")
    assert f"for this long (default {rule.settle_s:g} s)" in shown
    assert f"nothing stored (default {rule.unit_timeout_s:g} s)" in shown
    assert _params("station")["settle_s"] is None and _params("station")["unit_timeout_s"] is None


def test_waits_left_out_are_the_watch_rules_and_given_ones_are_kept() -> None:
    assert _watch_rule(True, 12, None, None, None) == WatchRule(12)
    assert _watch_rule(True, None, "DONE", 0.0, 30.0) == WatchRule(
        None, "DONE", settle_s=0.0, unit_timeout_s=30.0
    )
    assert _watch_rule(False, None, None, None, None) is None


@pytest.mark.parametrize("command", ["station", "calibrate", "solve"])
def test_the_model_shown_as_default_is_the_solves(command: str) -> None:
    assert _params(command)["model"] == DEFAULT_MODEL == StationRequest("A17", "shots/{serial}").model


def test_the_synth_help_names_the_synth_workflows_view_counts() -> None:
    shown = _help("synth")
    assert f"Default {DEFAULT_VIEWS} (video: {DEFAULT_VIDEO_KEYS})." in shown
    assert f"(--views = frames, default {DEFAULT_RIG_FRAMES})" in shown
