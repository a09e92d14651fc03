"""The calibctl command line: global options, command registration and the one error boundary."""

from __future__ import annotations

import os
import signal
import sys
import traceback
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer

# typer vendors its own click; its Context is the one the group's invoke receives.
from typer._click.core import Context as ClickContext  # noqa: PLC2701
from typer.core import TyperGroup

from calibctl import __version__
from calibctl.bounded import printable
from calibctl.cli import startup_interrupt
from calibctl.cli.context import AppState
from calibctl.cli.examples import epilog
from calibctl.cli.registry import CommandsOnDemand
from calibctl.cli.streams import flush_stdout_at_exit, make_output_safe, silence_closed_stdout
from calibctl.errors import EXIT_CANNOT_RUN, CalibctlError
from calibctl.files import ENVIRONMENT_ERRNOS, os_error


def _report(exc: CalibctlError) -> NoReturn:
    print(
        f"Error: {printable(exc.message)}", file=sys.stderr
    )  # a hostile file name cannot drive the terminal
    if exc.hint:
        print(f"Hint: {printable(exc.hint)}", file=sys.stderr)
    raise typer.Exit(exc.exit_code) from exc


class CalibctlGroup(TyperGroup):
    """The error boundary: CalibctlError -> 'Error: ...' + 'Hint: ...' on stderr and its exit code.

    Living in the group (not in ``run``) means CliRunner tests see exactly what users see. It is the
    root only: its sub-commands are imported and made on demand (``calibctl.cli.registry``).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.commands = CommandsOnDemand(
            {
                "pretty_exceptions_short": app.pretty_exceptions_short,
                "rich_markup_mode": self.rich_markup_mode,
                "suggest_commands": self.suggest_commands,
            }
        )

    def list_commands(self, ctx: ClickContext) -> list[str]:
        return list(self.commands)  # TyperGroup's walks the items, which would make every command

    def invoke(self, ctx: ClickContext) -> Any:
        make_output_safe()
        if (
            signal.getsignal(signal.SIGINT) is startup_interrupt
        ):  # from here Ctrl-C is KeyboardInterrupt, below
            signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            return super().invoke(ctx)
        except CalibctlError as exc:
            _report(exc)
        except BrokenPipeError:
            # The reader of stdout went away (`calibctl export X | head -1`): stop quietly.
            raise typer.Exit(silence_closed_stdout()) from None
        except OSError as exc:
            # A file-system problem (permission, read-only, disk full, ...) is the machine's, not a bug.
            if exc.errno not in ENVIRONMENT_ERRNOS:
                traceback.print_exc()
                raise typer.Exit(EXIT_CANNOT_RUN) from None
            _report(os_error(exc, "access"))
        # This typer vendors click: its Exit/Abort/usage errors are typer's own classes, not click's.
        except (typer.Exit, typer.Abort, typer.TyperException):
            raise
        except KeyboardInterrupt:
            print("Interrupted; nothing half-written was kept.", file=sys.stderr)
            raise typer.Exit(130) from None
        except Exception:
            # A bug: keep the traceback, and never exit 1 (which means "verdict: fail").
            traceback.print_exc()
            raise typer.Exit(EXIT_CANNOT_RUN) from None

    def make_context(
        self, info_name: str | None, args: list[str], parent: ClickContext | None = None, **extra: Any
    ) -> ClickContext:
        # The root's --help and --version are written while parsing, before invoke.
        try:
            return super().make_context(info_name, args, parent, **extra)
        except BrokenPipeError:
            raise typer.Exit(silence_closed_stdout()) from None


app = typer.Typer(  # the root: global options; each sub-command's module registers it (cli.registry)
    name="calibctl",
    cls=CalibctlGroup,
    help="Factory-line camera calibration with gates, honest uncertainty and an immutable artifact store.",
    epilog=epilog(""),
    no_args_is_help=True,
    add_completion=True,  # --install-completion / --show-completion for bash, zsh, fish, PowerShell
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def version_line() -> str:
    """calibctl's version and the OpenCV and numpy it runs on (cv2 is imported only for this)."""
    import platform

    import cv2
    import numpy

    return (
        f"calibctl {__version__} (OpenCV {cv2.__version__}, numpy {numpy.__version__}, "
        f"Python {platform.python_version()})"
    )


def _version(value: bool) -> None:
    if value:
        print(version_line())
        raise typer.Exit(0)


@app.callback()
def main(
    ctx: typer.Context,
    db: Annotated[
        str | None,
        typer.Option(
            "--db", help="Store URL (default sqlite:///calibctl.db; env CALIBCTL_DB).", show_default=False
        ),
    ] = None,
    station_config: Annotated[
        Path | None,
        typer.Option(
            "--station-config", help="Station YAML with gate/lint overrides (env CALIBCTL_STATION_CONFIG)."
        ),
    ] = None,
    json_output: Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")] = False,
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            callback=_version,
            is_eager=True,
            help="Print calibctl's version, the OpenCV and numpy it uses, and exit.",
        ),
    ] = False,
) -> None:
    ctx.obj = AppState(db=db, station_config=station_config, json_output=json_output)


PYDANTIC_PLUGINS_ENV = "PYDANTIC_DISABLE_PLUGINS"
"""calibctl's models use no pydantic plugin. Unset, pydantic reads the entry points of every installed
distribution when the first model is built (2-3 ms of each read command's start,
benchmarks/results/startup.md);
the command line sets it to ``__all__`` unless the user set it (``""`` or a list of names turns plugins back
on)."""


def run() -> None:
    os.environ.setdefault(PYDANTIC_PLUGINS_ENV, "__all__")
    try:
        app()
    finally:
        flush_stdout_at_exit()
