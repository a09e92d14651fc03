"""The root's sub-commands on demand: import the one module that registers a command, make that command.

typer makes every command of a group when it makes the group, reading each signature and its type
hints (62-66 ms of CPU for calibctl's 37, benchmarks/results/startup.md), and the CLI imported every command
module to register them first. The root group looks a command up here instead; ``--help``, shell completion
and a mistyped name still see every command.
The commands made, their help and their order are typer's own.
"""

from __future__ import annotations

import functools
import importlib
import math
from collections.abc import Callable, Iterator, MutableMapping
from typing import Any

import typer
import typer.main
from typer._click.core import Command as ClickCommand  # noqa: PLC2701 - typer vendors its own click

from calibctl.cli.examples import attach_examples
from calibctl.errors import UsageError

COMMAND_MODULES: dict[str, str] = {
    "capture": "capture",
    "calibrate": "capture",
    "prune": "capture",
    "synth": "capture",
    "solve": "solve",
    "check": "check",
    "diff": "diff",
    "lint": "lint",
    "history": "artifacts",
    "show": "artifacts",
    "export": "artifacts",
    "import": "artifacts",
    "rollback": "artifacts",
    "report": "report_page",
    "triage": "diagnostics",
    "gauge": "diagnostics",
    "timeoffset": "diagnostics",
    "synth-residuals": "diagnostics",
    "handeye": "handeye",
    "synth-motions": "handeye",
    "demo": "demo",
    "station": "station",
    "board": "board",
    "rig": "rig",
    "lidar": "lidar",
    "imu": "imu",
    "db": "db",
    "keys": "keys",
    "fleet": "fleet",
}
"""Each command or command group -> the ``calibctl.cli`` module whose ``register`` adds it; this order is
the order in ``--help`` (tests/cli/app/test_cli_registry.py holds it to what the modules register)."""


def makers(registry: typer.Typer, style: dict[str, Any]) -> dict[str, Callable[[], ClickCommand]]:
    """Name -> how typer makes that command or group from ``registry``, in typer's order (commands, then
    groups); ``style`` is the root's pretty_exceptions_short, rich_markup_mode and suggest_commands."""
    command_style = {k: v for k, v in style.items() if k != "suggest_commands"}
    out: dict[str, Callable[[], ClickCommand]] = {}
    for info in registry.registered_commands:
        assert info.callback is not None  # noqa: S101 - typer's own precondition
        name = info.name or typer.main.get_command_name(info.callback.__name__)
        out[name] = functools.partial(typer.main.get_command_from_info, info, **command_style)
    for group in registry.registered_groups:
        assert group.name  # noqa: S101 - every calibctl group is added with its name
        out[group.name] = functools.partial(typer.main.get_group_from_info, group, **style)
    return out


@functools.cache
def module_registry(module: str) -> typer.Typer:
    """What ``calibctl.cli.<module>`` registers, with each command's examples in its epilog."""
    registry = typer.Typer()
    importlib.import_module(f"calibctl.cli.{module}").register(registry)
    attach_examples(registry)
    return registry


MAX_ABS_OPTION = 1e12
"""No float option of calibctl (mm, px, deg, s, Hz, ppm) means anything beyond this magnitude."""


def _check_numbers(command: ClickCommand, values: dict[str, Any]) -> None:
    """UsageError (exit 2) for a float option the user gave as nan, inf or beyond ``MAX_ABS_OPTION``: typer
    accepts 'nan' and 'inf' as floats (and inside a range: nan compares false), and nan amplitudes wrote nan
    files with exit 0, inf ended in tracebacks."""
    flags = {p.name: (p.opts[0] if getattr(p, "opts", None) else p.name) for p in command.params}
    defaults = {p.name: p.default for p in command.params}
    for name, value in values.items():
        if name in defaults and value == defaults[name]:  # calibctl's own default (e.g. --range-m inf = rays)
            continue
        for v in value if isinstance(value, tuple | list) else (value,):
            if isinstance(v, float) and not (math.isfinite(v) and abs(v) <= MAX_ABS_OPTION):
                raise UsageError(
                    f"{flags.get(name, name)} {v!r} is not a usable number",
                    f"give a finite value of at most {MAX_ABS_OPTION:g} in magnitude",
                )


def guard_numbers(command: ClickCommand) -> ClickCommand:
    """``command`` (and every sub-command of a group) refusing non-finite float options before it runs."""
    for sub in getattr(command, "commands", {}).values():
        guard_numbers(sub)
    inner = command.callback
    if inner is not None and not getattr(inner, "_numbers_guarded", False):

        @functools.wraps(inner)
        def checked(*args: Any, **kwargs: Any) -> Any:
            _check_numbers(command, kwargs)
            return inner(*args, **kwargs)

        checked._numbers_guarded = True  # type: ignore[attr-defined]
        command.callback = checked
    return command


def _make(name: str, style: dict[str, Any]) -> ClickCommand:
    return guard_numbers(makers(module_registry(COMMAND_MODULES[name]), style)[name]())


class CommandsOnDemand(MutableMapping[str, ClickCommand]):
    """The root's sub-commands by name (a group's ``commands``); each is made when first looked up."""

    def __init__(self, style: dict[str, Any]) -> None:
        self._makers: dict[str, Callable[[], ClickCommand]] = {
            name: functools.partial(_make, name, style) for name in COMMAND_MODULES
        }
        self._made: dict[str, ClickCommand] = {}

    def __getitem__(self, name: str) -> ClickCommand:
        if name not in self._made:
            self._made[name] = self._makers[name]()  # KeyError for an unknown name, as a dict's
        return self._made[name]

    def __setitem__(self, name: str, command: ClickCommand) -> None:
        self._makers[name] = lambda: command
        self._made[name] = command

    def __delitem__(self, name: str) -> None:
        del self._makers[name]
        self._made.pop(name, None)

    def __contains__(self, name: object) -> bool:
        return name in self._makers  # without making the command

    def __iter__(self) -> Iterator[str]:
        return iter(self._makers)

    def __len__(self) -> int:
        return len(self._makers)
