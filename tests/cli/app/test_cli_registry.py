"""The root makes its sub-commands on demand (calibctl.cli.registry): the same commands, names and order."""

from __future__ import annotations

import importlib

import typer
import typer.main
from typer.models import TyperInfo

from calibctl.cli.examples import attach_examples
from calibctl.cli.main import app
from calibctl.cli.registry import COMMAND_MODULES, makers

STYLE = {
    "pretty_exceptions_short": app.pretty_exceptions_short,
    "rich_markup_mode": app.rich_markup_mode,
    "suggest_commands": app.suggest_commands,
}


def test_the_table_names_each_command_by_the_module_that_registers_it() -> None:
    registered = {}
    for module in dict.fromkeys(COMMAND_MODULES.values()):
        registry = typer.Typer()
        importlib.import_module(f"calibctl.cli.{module}").register(registry)
        registered |= dict.fromkeys(makers(registry, STYLE), module)
    assert registered == COMMAND_MODULES  # every command, each from its module, nothing else


def _described(command) -> tuple:
    subs = getattr(command, "commands", {})
    return (
        command.name,
        command.help,
        command.epilog,
        [(p.name, p.opts, p.default) for p in command.params],
        {name: _described(sub) for name, sub in subs.items()},
    )


def test_the_root_lists_every_command_in_the_tables_order_and_makes_what_typer_makes() -> None:
    every = typer.Typer()  # what typer makes when one app holds every registration, as before
    for module in dict.fromkeys(COMMAND_MODULES.values()):
        importlib.import_module(f"calibctl.cli.{module}").register(every)
    attach_examples(every)
    eager = typer.main.get_group_from_info(TyperInfo(every), **STYLE)
    root = typer.main.get_command(app)
    assert isinstance(root, typer.core.TyperGroup)
    assert root.list_commands(typer.Context(root)) == list(eager.commands) == list(COMMAND_MODULES)
    for name in COMMAND_MODULES:
        assert _described(root.commands[name]) == _described(eager.commands[name])
        assert root.commands[name].epilog  # its examples (calibctl.cli.examples) are attached
    assert "histroy" not in root.commands and root.commands.get("histroy") is None


def test_a_mistyped_command_is_named_with_a_suggestion_and_exits_2() -> None:
    from typer.testing import CliRunner

    res = CliRunner().invoke(app, ["histroy", "CAM-1"])
    assert res.exit_code == 2
    assert "No such command 'histroy'. Did you mean 'history'?" in res.output
